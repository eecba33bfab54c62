//! Progress of a long computation, reported to an observer the caller installs (a front end's
//! spinner or a Python callback).
//!
//! The same per-thread pattern as [`super::cancel`]: a front end runs the work inside
//! [`with_observer`], and the work calls [`report`] at its natural points:
//!
//! - the tuning pipeline at the start of each step ([`Progress::Stage`]);
//! - the least-squares solver ([`super::lsq`]) at every iteration ([`Progress::Search`]: the
//!   residual evaluations so far and the current cost).
//!
//! Without an observer [`report`] costs one thread-local read and builds nothing. An observer
//! is called on the thread that runs the work, synchronously: it should return quickly (a
//! spinner's message, a throttled print). The reports never change a result.

use std::cell::RefCell;
use std::sync::Arc;

/// What a computation reports.
#[derive(Debug, Clone, PartialEq)]
pub enum Progress {
    /// A stage begins (a tuning step: "step 5 (static parameters by cost (77))").
    Stage {
        /// The stage's name, for a display.
        name: String,
    },
    /// An iteration of a least-squares search.
    Search {
        /// Residual evaluations of this search so far.
        evaluations: usize,
        /// Its current cost (half the sum of squared residuals).
        cost: f64,
    },
}

/// A progress observer.
pub type Observer = Arc<dyn Fn(&Progress) + Send + Sync>;

thread_local! {
    static CURRENT: RefCell<Option<Observer>> = const { RefCell::new(None) };
}

/// Run `f` on this thread with `observer` receiving its [`report`]s; the previous observer
/// (usually none) is restored afterwards.
pub fn with_observer<R>(observer: &Observer, f: impl FnOnce() -> R) -> R {
    super::with_thread_value(&CURRENT, observer, f)
}

/// Report progress to the calling thread's observer, if any (`what` is called only then).
pub fn report(what: impl FnOnce() -> Progress) {
    // the observer is cloned out of the cell first: it may itself report
    let obs = CURRENT.with(|c| c.borrow().clone());
    if let Some(obs) = obs {
        obs(&what());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn reports_reach_the_observer_of_their_thread_only() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let s = seen.clone();
        let obs: Observer = Arc::new(move |p: &Progress| s.lock().unwrap().push(p.clone()));
        report(|| panic!("built without an observer"));
        with_observer(&obs, || {
            report(|| Progress::Stage { name: "a".into() });
            std::thread::scope(|t| {
                t.spawn(|| report(|| panic!("another thread has no observer")))
                    .join()
                    .unwrap()
            });
            report(|| Progress::Search {
                evaluations: 3,
                cost: 0.5,
            });
        });
        report(|| panic!("the scope has ended"));
        assert_eq!(
            *seen.lock().unwrap(),
            vec![
                Progress::Stage { name: "a".into() },
                Progress::Search {
                    evaluations: 3,
                    cost: 0.5
                }
            ]
        );
    }
}
