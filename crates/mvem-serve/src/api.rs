//! Routes, request parsing, errors and the bounded work queue.

use crate::compute::{self, Fail, MapRequest, MarginsRequest, SimulateRequest, StepRequest};
use crate::{Limits, Models};
use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, QueryRejection};
use axum::extract::{DefaultBodyLimit, Query, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use mvem::analysis::discrete::{check_ts, TS_MAX, TS_MIN};
use mvem::model::{AnyModel, Drive, Model, ModelOrder};
use mvem::numerics::cancel::{self, CancelToken};
use serde::de::DeserializeOwned;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use tokio::sync::Semaphore;

/// An error answer: status and `{"error": message}`.
#[derive(Debug)]
pub(crate) struct ApiError {
    status: StatusCode,
    message: String,
    retry_after: Option<u32>,
}

impl ApiError {
    fn new(status: StatusCode, message: impl Into<String>) -> Self {
        Self {
            status,
            message: message.into(),
            retry_after: None,
        }
    }

    fn bad(message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, message)
    }

    fn busy(message: impl Into<String>) -> Self {
        Self {
            retry_after: Some(1),
            ..Self::new(StatusCode::SERVICE_UNAVAILABLE, message)
        }
    }
}

impl From<Fail> for ApiError {
    fn from(f: Fail) -> Self {
        match f {
            Fail::Input(m) => Self::bad(m),
            Fail::Model(m) => Self::new(StatusCode::UNPROCESSABLE_ENTITY, m),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut r = (self.status, Json(json!({"error": self.message}))).into_response();
        if let Some(s) = self.retry_after {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        r
    }
}

type ApiResult = Result<Json<Value>, ApiError>;

/// Bounded concurrent work: `workers` computations at once on the blocking pool, at most
/// `max_queue` more waiting; beyond that, and after the time limit, 503 with `Retry-After`.
struct Work {
    permits: Arc<Semaphore>,
    pending: AtomicUsize,
    limits: Limits,
}

/// Cancels the computation's token when the request ends: answered (the computation is over),
/// timed out or dropped (the client went away), so a computation that polls the token (the
/// integrator before each step, the loop margins along a cycle before each sample:
/// `mvem::numerics::cancel`) stops and frees its worker instead of running on unseen.
struct CancelOnDrop(CancelToken);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.cancel();
    }
}

/// Decrements the pending count when a request leaves the queue (also on cancellation).
struct Pending<'a>(&'a AtomicUsize);

impl Drop for Pending<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

impl Work {
    async fn run<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, ApiError> {
        let cap = self.limits.workers + self.limits.max_queue;
        if self.pending.fetch_add(1, Ordering::AcqRel) >= cap {
            self.pending.fetch_sub(1, Ordering::AcqRel);
            return Err(ApiError::busy(format!(
                "server busy: {cap} requests running or queued; retry later"
            )));
        }
        let _pending = Pending(&self.pending);
        let token = CancelToken::new();
        let _cancel = CancelOnDrop(token.clone());
        let limit = self.limits.request_timeout;
        let deadline = tokio::time::Instant::now() + limit;
        let permit = tokio::time::timeout_at(deadline, self.permits.clone().acquire_owned())
            .await
            .map_err(|_| ApiError::busy("server busy: waited too long for a worker"))?
            .map_err(|_| ApiError::busy("server shutting down"))?;
        // the permit moves into the computation: it is released only when the work ends, even
        // if the request gave up waiting for it (cancelled then: see `CancelOnDrop`)
        let task = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            cancel::with_token(&token, f)
        });
        match tokio::time::timeout_at(deadline, task).await {
            Err(_) => Err(ApiError::busy(format!(
                "the computation took longer than {} s",
                limit.as_secs_f64()
            ))),
            Ok(Err(_)) => Err(ApiError::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                "internal error: the computation failed (a bug; please report the request)",
            )),
            Ok(Ok(v)) => Ok(v),
        }
    }
}

struct App {
    models: Arc<Models>,
    work: Work,
}

type Shared = Arc<App>;

/// The router with every route and limit.
pub(crate) fn router(models: Arc<Models>, limits: Limits) -> Router {
    let max_body = limits.max_body;
    let app = Arc::new(App {
        models,
        work: Work {
            permits: Arc::new(Semaphore::new(limits.workers.max(1))),
            pending: AtomicUsize::new(0),
            limits,
        },
    });
    Router::new()
        .route("/", get(index))
        .route("/app.js", get(app_js))
        .route("/app.css", get(app_css))
        .route("/api/health", get(health))
        .route("/api/models", get(models_info))
        .route("/api/steady", get(steady))
        .route("/api/linearize", get(linearize))
        .route("/api/step", post(step))
        .route("/api/margins", post(margins))
        .route("/api/simulate", post(simulate))
        .route("/api/map", post(map))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(max_body))
        .with_state(app)
}

// ---------------------------------------------------------------------------------------------
// Static files (embedded)

const INDEX_HTML: &str = include_str!("../assets/index.html");
const APP_JS: &str = include_str!("../assets/app.js");
const APP_CSS: &str = include_str!("../assets/app.css");

fn asset(body: &'static str, content_type: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

async fn index() -> Response {
    asset(INDEX_HTML, "text/html; charset=utf-8")
}

async fn app_js() -> Response {
    asset(APP_JS, "text/javascript; charset=utf-8")
}

async fn app_css() -> Response {
    asset(APP_CSS, "text/css; charset=utf-8")
}

async fn not_found() -> ApiError {
    ApiError::new(StatusCode::NOT_FOUND, "no such route; see docs/serve.md")
}

/// A route asked with another method (GET of a POST route ...): 405 with a JSON body, as every
/// answer of the server (axum's own has none).
async fn method_not_allowed(method: axum::http::Method, uri: axum::http::Uri) -> ApiError {
    let allowed = match uri.path() {
        "/api/step" | "/api/margins" | "/api/simulate" | "/api/map" => "POST",
        _ => "GET",
    };
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        format!(
            "{method} {}: not allowed; the route takes {allowed} (docs/serve.md)",
            uri.path()
        ),
    )
}

// ---------------------------------------------------------------------------------------------
// Query strings

/// The parameters of a query string, taken one by one; what is left over is an error.
pub(crate) struct Params(Vec<(String, String)>);

impl Params {
    fn new(q: Result<Query<Vec<(String, String)>>, QueryRejection>) -> Result<Self, ApiError> {
        let Query(pairs) = q.map_err(|e| ApiError::bad(format!("query string: {e}")))?;
        for (i, (k, _)) in pairs.iter().enumerate() {
            if pairs[..i].iter().any(|(k2, _)| k2 == k) {
                return Err(ApiError::bad(format!("{k}: given more than once")));
            }
        }
        Ok(Self(pairs))
    }

    fn take(&mut self, name: &str) -> Option<String> {
        let i = self.0.iter().position(|(k, _)| k == name)?;
        Some(self.0.swap_remove(i).1)
    }

    /// A required finite number.
    fn number(&mut self, name: &str, what: &str) -> Result<f64, ApiError> {
        let s = self
            .take(name)
            .ok_or_else(|| ApiError::bad(format!("{name}: missing (required: {what})")))?;
        let v: f64 = s
            .trim()
            .parse()
            .map_err(|_| ApiError::bad(format!("{name}: not a number: {s:?}")))?;
        if !v.is_finite() {
            return Err(ApiError::bad(format!("{name} {s}: must be finite")));
        }
        Ok(v)
    }

    /// The operating point `n_e`, `u_delta`, `u_egr`, `u_vgt`.
    fn drive(&mut self) -> Result<Drive, ApiError> {
        Ok(Drive::new(
            self.number("n_e", "engine speed in rpm")?,
            self.number("u_delta", "injected fuel in mg/cycle")?,
            self.number("u_egr", "EGR valve command in %")?,
            self.number("u_vgt", "VGT command in %")?,
        ))
    }

    /// Refuse what was not taken.
    fn finish(self, known: &str) -> Result<(), ApiError> {
        match self.0.first() {
            None => Ok(()),
            Some((k, _)) => Err(ApiError::bad(format!(
                "{k}: unknown parameter (known: {known})"
            ))),
        }
    }
}

/// `model=8|10|12`.
fn order(v: Option<&str>) -> Result<ModelOrder, ApiError> {
    match v.map(str::trim) {
        None | Some("8") => Ok(ModelOrder::Eight),
        Some("10") => Ok(ModelOrder::Ten),
        Some("12") => Ok(ModelOrder::Twelve),
        Some(o) => Err(ApiError::bad(format!("model {o:?}: one of 8, 10, 12"))),
    }
}

fn order_n(v: Option<u32>) -> Result<ModelOrder, ApiError> {
    order(v.map(|n| n.to_string()).as_deref())
}

impl App {
    /// The model chosen by `model` and `params` (a clone: models are small and immutable).
    fn model(&self, order: ModelOrder, params: Option<&str>) -> Result<AnyModel, ApiError> {
        self.models.get(params, order).cloned().ok_or_else(|| {
            ApiError::bad(format!(
                "params {:?}: not a parameter set of this server; one of {}",
                params.unwrap_or_default(),
                self.models.names().join(", ")
            ))
        })
    }
}

/// A JSON body, or 413 past the size limit `max` \[bytes\] / 400 naming what is wrong.
fn body<T: DeserializeOwned>(b: Result<Bytes, BytesRejection>, max: usize) -> Result<T, ApiError> {
    let b = b.map_err(|e| {
        let status = e.status();
        if status == StatusCode::PAYLOAD_TOO_LARGE {
            let limit = if max % (1 << 20) == 0 {
                format!("{} MiB", max >> 20)
            } else {
                format!("{max} bytes")
            };
            ApiError::new(status, format!("body: too large (the limit is {limit})"))
        } else {
            ApiError::bad(format!("body: {e}"))
        }
    })?;
    // the error names the field it is at (`body: margins: invalid type: string "often",
    // expected f64 ...`), nested ones by their path (`tuning.torque`)
    let mut de = serde_json::Deserializer::from_slice(&b);
    let v = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        if path == "." {
            ApiError::bad(format!("body: {}", e.inner()))
        } else {
            ApiError::bad(format!("body: {path}: {}", e.inner()))
        }
    })?;
    // nothing but white space after the value
    de.end().map_err(|e| ApiError::bad(format!("body: {e}")))?;
    Ok(v)
}

// ---------------------------------------------------------------------------------------------
// Handlers

async fn health(State(app): State<Shared>) -> Json<Value> {
    Json(json!({
        "status": "ok",
        "version": env!("CARGO_PKG_VERSION"),
        "busy": app.work.pending.load(Ordering::Acquire),
    }))
}

async fn models_info(State(app): State<Shared>) -> Json<Value> {
    let mut names: Vec<&str> = Drive::NAMES.to_vec();
    if let Some(m) = app.models.get(None, ModelOrder::Twelve) {
        names.extend(mvem::dispatch!(m, m => m.state_names().to_vec()));
    }
    names.extend(mvem::model::Signals::NAMES);
    let mut units: serde_json::Map<String, Value> = names
        .into_iter()
        .map(|n| (n.to_string(), json!(mvem::analysis::json::unit(n))))
        .collect();
    // the closed loop's own columns (references, motoring flag)
    for n in mvem::control::Trajectory::NAMES {
        units
            .entry(n)
            .or_insert_with(|| json!(mvem::control::Trajectory::unit(n)));
    }
    Json(json!({
        "units": units,
        "orders": [8, 10, 12],
        "params": app.models.names(),
        // per parameter set, the n_e, u_delta, u_egr and u_vgt ranges its model clamps into
        // (its input_saturation): the explorer's sliders span them
        "input_ranges": app
            .models
            .names()
            .into_iter()
            .filter_map(|n| {
                let m = app.models.get(Some(n), ModelOrder::Eight)?;
                let s = &m.params().input_saturation;
                Some((
                    n.to_string(),
                    json!({"n_e": s.n_e, "u_delta": s.u_delta, "u_egr": s.u_egr, "u_vgt": s.u_vgt}),
                ))
            })
            .collect::<serde_json::Map<String, Value>>(),
        "cycles": app.models.cycles.iter().map(|(n, _)| n).collect::<Vec<_>>(),
        "modes": compute::CycleMode::NAMES,
        // the baseline controllers' tuning of the closed-loop mode: the defaults and, per field
        // a user sets, its unit and description (the page's tuning form)
        "controller_tuning": {
            "defaults": mvem::control::baseline::BaselineTuning::default(),
            // with the interval each value must lie in (BaselineTuning::BOUNDS, in the same
            // order): "lo", "hi", "lo_open", "hi_open" and the notation "interval"
            "fields": mvem::control::baseline::BaselineTuning::FIELDS
                .iter()
                .zip(mvem::control::baseline::BaselineTuning::BOUNDS)
                .map(|(f, (_, b))| json!({
                    "name": f.name, "unit": f.unit, "description": f.description,
                    "bounds": {"lo": b.lo, "hi": b.hi, "lo_open": b.lo_open, "hi_open": b.hi_open,
                               "interval": b.interval()},
                }))
                .collect::<Vec<_>>(),
        },
        "limits": {
            "max_body": app.work.limits.max_body,
            "map_side": compute::MAX_MAP_SIDE,
            "map_points": compute::MAX_MAP_POINTS,
        },
    }))
}

const POINT_KEYS: &str = "n_e, u_delta, u_egr, u_vgt, model, params";

async fn steady(
    State(app): State<Shared>,
    q: Result<Query<Vec<(String, String)>>, QueryRejection>,
) -> ApiResult {
    let mut p = Params::new(q)?;
    let d = p.drive()?;
    let o = order(p.take("model").as_deref())?;
    let m = app.model(o, p.take("params").as_deref())?;
    p.finish(POINT_KEYS)?;
    let v = app
        .work
        .run(move || mvem::dispatch!(&m, m => compute::steady(m, &d)))
        .await??;
    Ok(Json(v))
}

async fn linearize(
    State(app): State<Shared>,
    q: Result<Query<Vec<(String, String)>>, QueryRejection>,
) -> ApiResult {
    let mut p = Params::new(q)?;
    let d = p.drive()?;
    let o = order(p.take("model").as_deref())?;
    let m = app.model(o, p.take("params").as_deref())?;
    let pade = match p.take("pade") {
        None => 0,
        Some(s) => match s.trim().parse::<usize>() {
            Ok(k) if k <= 3 => k,
            _ => return Err(ApiError::bad(format!("pade {s:?}: one of 0, 1, 2, 3"))),
        },
    };
    // each name once (the first), at most as many as a simulation's series
    let mut outputs: Vec<String> = Vec::new();
    for x in p.take("outputs").unwrap_or_default().split(',') {
        let x = x.trim();
        if !x.is_empty() && !outputs.iter().any(|o| o == x) {
            outputs.push(x.to_string());
        }
    }
    if outputs.len() > compute::MAX_OUTPUTS {
        return Err(ApiError::bad(format!(
            "outputs: {} names, at most {}",
            outputs.len(),
            compute::MAX_OUTPUTS
        )));
    }
    // the model sampled at ts [s] with the delays exact (`mvem linearize --ts`)
    let ts = match p.take("ts") {
        None => None,
        Some(s) => match s.trim().parse::<f64>() {
            Ok(v) if check_ts(v).is_ok() && pade == 0 => Some(v),
            Ok(v) if check_ts(v).is_ok() => {
                return Err(ApiError::bad(
                    "ts with pade: the sampled model has the delays exact; leave out pade",
                ))
            }
            _ => {
                return Err(ApiError::bad(format!(
                    "ts {s:?}: a sample time in [{TS_MIN}, {TS_MAX}] s"
                )))
            }
        },
    };
    // the frequency response with the delays exact (`mvem linearize --bode FMIN:FMAX:N`)
    let bode = match p.take("bode") {
        None => None,
        Some(_) if pade > 0 => {
            return Err(ApiError::bad(
                "bode with pade: the frequency response has the delays exact; leave out pade",
            ))
        }
        Some(s) => Some(bode_grid(&s)?),
    };
    p.finish("n_e, u_delta, u_egr, u_vgt, model, params, pade, outputs, ts, bode")?;
    let v = app
        .work
        .run(move || {
            mvem::dispatch!(&m, m => compute::linearize(m, &d, pade, &outputs, ts, bode.as_deref()))
        })
        .await??;
    Ok(Json(v))
}

/// Most frequencies of one `bode` request (a figure needs a few hundred).
const MAX_BODE_POINTS: usize = 2000;
/// The frequency range of a `bode` request \[Hz\]: eight decades around the engine's dynamics
/// (its poles lie between some 0.01 and 100 Hz); beyond them a figure is unreadable.
const BODE_RANGE_HZ: (f64, f64) = (1e-4, 1e4);

/// The frequencies of `bode=FMIN:FMAX:N` (Hz, log-spaced) inside [`BODE_RANGE_HZ`].
fn bode_grid(spec: &str) -> Result<Vec<f64>, ApiError> {
    let f = mvem::analysis::frequency::parse_grid(spec, MAX_BODE_POINTS)
        .map_err(|e| ApiError::bad(format!("bode {spec:?}: {e}")))?;
    let (lo, hi) = BODE_RANGE_HZ;
    if f.iter().any(|&v| !(lo..=hi).contains(&v)) {
        return Err(ApiError::bad(format!(
            "bode {spec:?}: the frequencies must lie in [{lo}, {hi}] Hz (mvem linearize --bode \
             has no such limit)"
        )));
    }
    Ok(f)
}

async fn step(State(app): State<Shared>, b: Result<Bytes, BytesRejection>) -> ApiResult {
    let r: StepRequest = body(b, app.work.limits.max_body)?;
    let slot = r.check()?;
    let m = app.model(order_n(r.model)?, r.params.as_deref())?;
    let v = app
        .work
        .run(move || mvem::dispatch!(&m, m => compute::step(m, &r, slot)))
        .await??;
    Ok(Json(v))
}

async fn margins(State(app): State<Shared>, b: Result<Bytes, BytesRejection>) -> ApiResult {
    let r: MarginsRequest = body(b, app.work.limits.max_body)?;
    let m = app.model(order_n(r.model)?, r.params.as_deref())?;
    let v = app
        .work
        .run(move || mvem::dispatch!(&m, m => compute::margins(m, &r)))
        .await??;
    Ok(Json(v))
}

async fn simulate(State(app): State<Shared>, b: Result<Bytes, BytesRejection>) -> ApiResult {
    let r: SimulateRequest = body(b, app.work.limits.max_body)?;
    let m = app.model(order_n(r.model)?, r.params.as_deref())?;
    let (what, name, dt) = r.schedule(&app.models.cycles)?;
    let v = app
        .work
        .run(move || compute::simulate_cycle(&m, &r, &what, &name, dt))
        .await??;
    Ok(Json(v))
}

async fn map(State(app): State<Shared>, b: Result<Bytes, BytesRejection>) -> ApiResult {
    let r: MapRequest = body(b, app.work.limits.max_body)?;
    let grid = r.grid()?;
    let m = app.model(order_n(r.model)?, r.params.as_deref())?;
    let v = app
        .work
        .run(move || mvem::dispatch!(&m, m => compute::map(m, &r, &grid)))
        .await??;
    Ok(Json(v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    /// A computation still running when its request times out sees its cancellation token (so
    /// that it can stop and free its worker); one that ends in time is not cancelled.
    #[test]
    fn a_timed_out_computation_sees_its_token_cancelled() {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()
            .unwrap();
        let work = Work {
            permits: Arc::new(Semaphore::new(1)),
            pending: AtomicUsize::new(0),
            limits: Limits {
                request_timeout: Duration::from_millis(200),
                ..Limits::default()
            },
        };
        let (tx, rx) = std::sync::mpsc::channel();
        let r = rt.block_on(work.run(move || {
            let t = Instant::now();
            while !cancel::requested() && t.elapsed() < Duration::from_secs(30) {
                std::thread::sleep(Duration::from_millis(1));
            }
            let _ = tx.send((cancel::requested(), t.elapsed()));
        }));
        assert_eq!(r.unwrap_err().status, StatusCode::SERVICE_UNAVAILABLE);
        let (seen, after) = rx
            .recv_timeout(Duration::from_secs(20))
            .expect("the computation stops");
        assert!(
            seen,
            "stopped after {after:?} without seeing the cancellation"
        );
        assert!(after < Duration::from_secs(10), "{after:?}");
        assert!(!rt.block_on(work.run(cancel::requested)).unwrap());
    }
}
