//! `mvem serve`: a local web explorer of the engine model.
//!
//! One HTTP server (axum on tokio, HTTP/1.1) serves a single-page app whose files are embedded
//! in the binary (`assets/`) and a JSON API that returns the same numbers as the CLI (the JSON
//! objects are built by [`mvem::analysis::json`] for both):
//!
//! | route | answer |
//! | --- | --- |
//! | `GET /api/health` | `{"status": "ok", ...}` |
//! | `GET /api/models` | the model orders and parameter sets the server was started with |
//! | `GET /api/steady?n_e=&u_delta=&u_egr=&u_vgt=[&model=&params=]` | `mvem steady --json` |
//! | `GET /api/linearize?...[&pade=&outputs=&ts=&bode=FMIN:FMAX:N]` | `mvem linearize --json` |
//! | `POST /api/step` | step responses and their metrics (`mvem step --json` plus the series) |
//! | `POST /api/simulate` | a drive cycle (the built-in WHTC or a CSV table), open loop or with the baseline controllers (`"mode": "closed"`, optionally with the loop margins along the run) |
//! | `POST /api/map` | DC gain and its sign of one channel over two inputs (parallel) |
//!
//! Safety: the server binds 127.0.0.1 unless told otherwise; request bodies are bounded
//! ([`Limits::max_body`], 413 beyond), every computation runs on a bounded pool of blocking
//! threads behind a queue of bounded length (503 with `Retry-After` when full) and a time limit
//! (after which the computation's cancellation token is cancelled: the integrator and the loop
//! margins along a cycle stop at their next check);
//! bad input gives 400 with `{"error": "..."}` naming the parameter; the API reads no file (the
//! parameter files are read once at start). Ctrl-C shuts the server down gracefully.
//! The routes and bodies are documented in `docs/serve.md`.

mod api;
pub mod client;
mod compute;

use mvem::model::{AnyModel, ModelOptions, ModelOrder};
use mvem::params::Params;
use mvem::sim::InputSchedule;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

pub use compute::{CycleMode, MAX_MAP_POINTS, MAX_MAP_SIDE, MAX_MARGINS_SAMPLES};

/// Bounds on what one request may ask.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Largest request body \[bytes\] (413 beyond).
    pub max_body: usize,
    /// Computations running at once (blocking threads).
    pub workers: usize,
    /// Computations waiting for a worker before the server answers 503.
    pub max_queue: usize,
    /// Longest time a request may wait and compute \[s\]; 503 after it.
    pub request_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
        Self {
            max_body: 4 << 20,
            workers: 2 * cores,
            max_queue: 256,
            request_timeout: Duration::from_secs(60),
        }
    }
}

/// What the server is started with.
#[derive(Debug, Clone)]
pub struct Config {
    /// Address to bind (host and port; port 0 picks a free one).
    pub addr: SocketAddr,
    /// Parameter sets by name; the API's `params=` chooses among them. The first is the default.
    pub params: Vec<(String, Params)>,
    /// Drive cycles by name (CSV text in the format of `mvem simulate --inputs`), parsed at
    /// start; `POST /api/simulate` chooses among them with `"cycle"`.
    pub cycles: Vec<(String, &'static str)>,
    /// Model options (the CLI's defaults: the authors' semantics, converged T_e, dynamic actuators).
    pub options: ModelOptions,
    /// Request limits.
    pub limits: Limits,
}

impl Config {
    /// 127.0.0.1:`port` with the published parameter set only.
    pub fn local(port: u16) -> Self {
        Self {
            addr: SocketAddr::from(([127, 0, 0, 1], port)),
            params: vec![("published".to_string(), Params::published())],
            cycles: Vec::new(),
            options: ModelOptions::default(),
            limits: Limits::default(),
        }
    }
}

/// Why the server could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The address could not be bound.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// Address asked for.
        addr: SocketAddr,
        /// OS error.
        source: std::io::Error,
    },
    /// A parameter set does not give a model.
    #[error("parameter set {name:?}: {source}")]
    Model {
        /// Name of the set.
        name: String,
        /// Why.
        source: mvem::model::ModelError,
    },
    /// Bad configuration.
    #[error("{0}")]
    Config(String),
    /// The runtime failed.
    #[error("server: {0}")]
    Io(#[from] std::io::Error),
}

/// The models the API chooses from (every parameter set in every order: 8, 10, 12 states)
/// and the drive cycles.
#[derive(Debug)]
pub(crate) struct Models {
    sets: Vec<(String, [AnyModel; 3])>,
    pub(crate) cycles: Vec<(String, Arc<InputSchedule>)>,
}

impl Models {
    fn build(config: &Config) -> Result<Self, ServeError> {
        if config.params.is_empty() {
            return Err(ServeError::Config("no parameter set".into()));
        }
        let mut sets = Vec::new();
        for (name, p) in &config.params {
            if sets.iter().any(|(n, _)| n == name) {
                return Err(ServeError::Config(format!(
                    "two parameter sets are named {name:?}"
                )));
            }
            let build = |o| {
                AnyModel::new(o, p.clone(), config.options).map_err(|source| ServeError::Model {
                    name: name.clone(),
                    source,
                })
            };
            sets.push((
                name.clone(),
                [
                    build(ModelOrder::Eight)?,
                    build(ModelOrder::Ten)?,
                    build(ModelOrder::Twelve)?,
                ],
            ));
        }
        let mut cycles = Vec::new();
        for (name, text) in &config.cycles {
            let s = mvem::io::csv_inputs::parse_inputs_csv(text, std::path::Path::new(name))
                .map_err(|e| ServeError::Config(format!("cycle {name:?}: {e}")))?;
            cycles.push((name.clone(), Arc::new(s)));
        }
        Ok(Self { sets, cycles })
    }

    /// Names of the parameter sets (the first is the default).
    pub(crate) fn names(&self) -> Vec<&str> {
        self.sets.iter().map(|(n, _)| n.as_str()).collect()
    }

    /// The model of the set `params` (default: the first) in `order`.
    pub(crate) fn get(&self, params: Option<&str>, order: ModelOrder) -> Option<&AnyModel> {
        let set = match params {
            None => self.sets.first(),
            Some(p) => self.sets.iter().find(|(n, _)| n == p),
        }?;
        Some(match order {
            ModelOrder::Eight => &set.1[0],
            ModelOrder::Ten => &set.1[1],
            ModelOrder::Twelve => &set.1[2],
        })
    }
}

/// A server running on a thread of its own (tests, the load benchmark).
pub struct Running {
    /// The bound address.
    pub addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<Result<(), ServeError>>>,
}

impl Running {
    /// Shut down gracefully (in-flight requests finish) and wait for the thread.
    pub fn stop(mut self) -> Result<(), ServeError> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Result<(), ServeError> {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(ServeError::Config("the server thread panicked".into())),
            None => Ok(()),
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.shutdown();
    }
}

fn runtime(limits: &Limits) -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        // the computations hold a permit (`Limits::workers`); a few more for the runtime's own use
        .max_blocking_threads(limits.workers + 4)
        .thread_name("mvem-serve")
        .enable_all()
        .build()
}

/// Start the server on a thread of its own; returns once it listens.
pub fn start(config: Config) -> Result<Running, ServeError> {
    let models = Arc::new(Models::build(&config)?);
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let thread = std::thread::Builder::new()
        .name("mvem-serve".into())
        .spawn(move || -> Result<(), ServeError> {
            let rt = runtime(&config.limits)?;
            rt.block_on(async move {
                let listener = match tokio::net::TcpListener::bind(config.addr).await {
                    Ok(l) => l,
                    Err(source) => {
                        let e = ServeError::Bind {
                            addr: config.addr,
                            source,
                        };
                        let _ = ready_tx.send(Err(e.to_string()));
                        return Err(e);
                    }
                };
                let _ = ready_tx.send(listener.local_addr().map_err(|e| e.to_string()));
                let app = api::router(models, config.limits.clone());
                axum::serve(listener, app)
                    .with_graceful_shutdown(async move {
                        let _ = stop_rx.await;
                    })
                    .await?;
                Ok(())
            })
        })?;
    match ready_rx.recv() {
        Ok(Ok(addr)) => Ok(Running {
            addr,
            stop: Some(stop_tx),
            thread: Some(thread),
        }),
        Ok(Err(_)) | Err(_) => match thread.join() {
            Ok(Err(e)) => Err(e),
            _ => Err(ServeError::Config("the server did not start".into())),
        },
    }
}

/// Run the server in the calling thread until Ctrl-C (or SIGTERM); `ready` is called with the
/// bound address once it listens.
pub fn run(config: Config, ready: impl FnOnce(SocketAddr)) -> Result<(), ServeError> {
    let models = Arc::new(Models::build(&config)?);
    let rt = runtime(&config.limits)?;
    rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(config.addr)
            .await
            .map_err(|source| ServeError::Bind {
                addr: config.addr,
                source,
            })?;
        // the handlers are installed before the address is announced: a Ctrl-C right after
        // "listening on ..." shuts down gracefully instead of killing the process
        let shutdown = shutdown_signal();
        ready(listener.local_addr()?);
        let app = api::router(models, config.limits.clone());
        axum::serve(listener, app)
            .with_graceful_shutdown(shutdown)
            .await?;
        Ok(())
    })
}

/// Ctrl-C or SIGTERM, with the signal handlers installed when this is called (inside the
/// runtime), not when the future is first polled.
fn shutdown_signal() -> impl std::future::Future<Output = ()> {
    #[cfg(unix)]
    let (int, term) = {
        use tokio::signal::unix::{signal, SignalKind};
        (
            signal(SignalKind::interrupt()).ok(),
            signal(SignalKind::terminate()).ok(),
        )
    };
    async move {
        #[cfg(unix)]
        {
            async fn recv(s: Option<tokio::signal::unix::Signal>) {
                match s {
                    Some(mut s) => {
                        s.recv().await;
                    }
                    None => std::future::pending::<()>().await,
                }
            }
            tokio::select! {
                _ = recv(int) => {},
                _ = recv(term) => {},
            }
        }
        #[cfg(not(unix))]
        {
            let _ = tokio::signal::ctrl_c().await;
        }
        eprintln!("shutting down (in-flight requests finish)");
    }
}
