//! Cancelling a long computation from another thread (a front end's Ctrl-C).
//!
//! A tuning runs for tens of seconds to minutes, an ensemble as long as its user asks. A front
//! end that runs one on a worker thread (the Python module does, so that Ctrl-C in a notebook
//! can stop `mvem.tune`) creates a [`CancelToken`], runs the work inside [`with_token`] on that
//! thread and calls [`CancelToken::cancel`] from its own. The work polls [`requested`] at its
//! natural checkpoints and stops with its own typed error:
//!
//! - the least-squares solver ([`super::lsq`]) before every residual evaluation and every
//!   Jacobian: [`super::lsq::LsqError::Cancelled`], which the tuning steps report as their
//!   failure, so a tuning stops within one residual evaluation (one round of simulations);
//! - the tuning pipeline between its steps;
//! - an ensemble ([`crate::analysis::ensemble::simulate_many`]) before each run: the runs not
//!   started report that they were cancelled.
//!
//! The token is per thread (set by [`with_token`] for the duration of one call, restored after
//! it, also when the call panics), so concurrent computations on different threads are cancelled
//! independently. Parallel code that wants its workers to see the caller's token takes it with
//! [`current`] before it fans out and polls that (rayon's workers are other threads), or wraps
//! its workers' closure in [`carry`]. Code that runs without a token is never cancelled, and
//! [`requested`] costs one thread-local read.
//!
//! - the integrator ([`crate::sim`]) before every trial step: [`crate::sim::SimError::Cancelled`]
//!   with the time and state reached (it takes the token when it is created; the time chunks of
//!   one run and the runs of an ensemble, the campaign's sets of the virtual test cell and of a
//!   validation carry it to their threads), so a long simulation stops within one step.

use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A cancellation request shared between the thread that runs a computation and the one that
/// may stop it. Clones share the request.
#[derive(Debug, Clone, Default)]
pub struct CancelToken(Arc<AtomicBool>);

impl CancelToken {
    /// A token that is not cancelled.
    pub fn new() -> Self {
        Self::default()
    }

    /// Ask the computations that poll this token to stop (idempotent).
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether [`Self::cancel`] was called on this token or a clone of it.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

thread_local! {
    static CURRENT: RefCell<Option<CancelToken>> = const { RefCell::new(None) };
}

/// Run `f` on this thread with `token` as the thread's cancellation token ([`requested`],
/// [`current`]); the previous token (usually none) is restored afterwards.
pub fn with_token<R>(token: &CancelToken, f: impl FnOnce() -> R) -> R {
    super::with_thread_value(&CURRENT, token, f)
}

/// The calling thread's token, if it runs inside [`with_token`].
pub fn current() -> Option<CancelToken> {
    CURRENT.with(|c| c.borrow().clone())
}

/// Whether the calling thread's token (if any) has been cancelled.
pub fn requested() -> bool {
    CURRENT.with(|c| c.borrow().as_ref().is_some_and(CancelToken::is_cancelled))
}

/// `f` made to run with the calling thread's token (taken now, by [`current`]) on whichever
/// thread calls it: for the closures of parallel iterators, whose workers are other threads
/// (`items.par_iter().map(carry(|x| simulate(x)))`), so that the integrators and searches they
/// run see the caller's cancellation. Without a token `f` runs as it is.
pub fn carry<A, R>(f: impl Fn(A) -> R + Sync + Send) -> impl Fn(A) -> R + Sync + Send {
    let token = current();
    move |a| with_token_if(token.as_ref(), || f(a))
}

/// [`with_token`] when there is a token (one taken with [`current`] on another thread), else
/// `f` as it is.
pub fn with_token_if<R>(token: Option<&CancelToken>, f: impl FnOnce() -> R) -> R {
    match token {
        Some(t) => with_token(t, f),
        None => f(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_token_is_seen_only_inside_its_scope_and_only_on_its_thread() {
        let t = CancelToken::new();
        assert!(!requested());
        with_token(&t, || {
            assert!(!requested());
            t.cancel();
            assert!(requested());
            // another thread has no token
            std::thread::scope(|s| s.spawn(|| assert!(!requested())).join().unwrap());
            // a nested scope with a fresh token hides the outer one, and restores it
            with_token(&CancelToken::new(), || assert!(!requested()));
            assert!(requested());
        });
        assert!(!requested());
        assert!(current().is_none());
    }

    #[test]
    fn a_carried_closure_sees_the_callers_token_on_another_thread() {
        let t = CancelToken::new();
        let f = with_token(&t, || carry(|k: u32| (k, requested())));
        t.cancel();
        let (k, seen) = std::thread::scope(|s| s.spawn(|| f(7)).join().unwrap());
        assert_eq!((k, seen), (7, true));
        // taken outside any scope: no token, on any thread
        let g = carry(|()| requested());
        assert!(!std::thread::scope(|s| s.spawn(|| g(())).join().unwrap()));
    }

    #[test]
    fn the_previous_token_is_restored_after_a_panic() {
        let t = CancelToken::new();
        t.cancel();
        let r = std::panic::catch_unwind(|| with_token(&t, || panic!("inside")));
        assert!(r.is_err());
        assert!(!requested());
    }
}
