//! The HTTP API (axum): routers, extractors, errors to responses. No math, no SQL.
//!
//! [`Application::build`] binds the listener first, so it knows its port before serving:
//! tests start the real server on `127.0.0.1:0` and read the port back.

pub mod auth;
mod bases;
pub mod budget;
mod error;
pub mod forward;
mod library;
mod metrics;
mod object;
pub mod proxy;
mod routes;
mod search;
pub mod serve;
mod skeletons;
mod streams;
mod takes;
mod tokens;
mod ui;
mod views;

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::DefaultBodyLimit;
use axum::handler::Handler;
use axum::http::StatusCode;
use axum::routing::get;
use axum::Router;
use tokio::net::TcpListener;
use tower_http::set_header::SetResponseHeaderLayer;
use tower_http::trace::TraceLayer;

use auth::{Front, Policy, RateKey};
use budget::{hold_body, BodyGate};
pub use error::ApiError;
pub use metrics::Metrics;
use routes::Routes;

use crate::limits::Limits;
use crate::service::access::{AuditLog, Authenticator, Scope};
use crate::service::budget::Budget;
use crate::service::history::Histories;
use crate::service::jobs::Jobs;
use crate::service::motion_index::MotionIndex;
use crate::service::prepared::ReadCaches;
use crate::service::streams::Streams;
use crate::service::Node;
use crate::store::Store;

/// How to run the service.
#[derive(Debug, Clone)]
pub struct Config {
    pub listen: String,
    pub database_url: String,
    /// Every bound on what clients send and what the server holds.
    pub limits: Limits,
    /// Memory for decoded chunks kept between range requests, MiB.
    pub decoded_cache_mib: usize,
    /// How long a live take stays live when its server stops renewing it (see
    /// [`Streams::lease`]); leases are renewed every [`MAINTENANCE_PERIOD`].
    pub stream_lease: Duration,
    /// How long a background job's lease lasts ([`crate::service::jobs`]): a job whose server
    /// has not renewed it for this long is run again by another server.
    pub job_lease: Duration,
    /// Encode every candidate of every take in full: no candidate is left out by what a
    /// layout's earlier takes say ([`crate::service::history`]).
    pub exhaustive_choice: bool,
    /// Browser origins allowed, and whether to serve anonymous requests beyond loopback.
    pub policy: Policy,
    /// A second address serving `GET /metrics` alone, without a token (for a scraper on an
    /// internal network); on the main address `/metrics` needs an admin token.
    pub metrics_listen: Option<String>,
    /// Reverse proxies whose `X-Forwarded-For` names the client ([`proxy`]).
    pub trusted_proxies: proxy::TrustedProxies,
    /// The address other servers on the same database reach this one at, to forward a
    /// live stream's requests to it (`http://host:port`); by default the address it
    /// listens on (loopback if it listens on every interface).
    pub advertise_url: Option<String>,
}

/// Connections the `--metrics-listen` address takes at once.
pub const METRICS_CONNECTIONS: u64 = 16;

/// How often the server renews its streams' leases (more often for leases under three
/// times this), finishes idle streams and closes the takes of streams whose server died.
pub const MAINTENANCE_PERIOD: Duration = Duration::from_secs(10);

/// How often a server looks for takes whose motion features are missing or stale, and
/// starts the index job if none runs.
pub const INDEX_PERIOD: Duration = Duration::from_secs(5);

impl Default for Config {
    fn default() -> Self {
        Config {
            listen: "127.0.0.1:8080".into(),
            database_url: "sqlite://mocapstore.db".into(),
            limits: Limits::default(),
            decoded_cache_mib: 256,
            stream_lease: Duration::from_secs(60),
            job_lease: crate::service::jobs::DEFAULT_LEASE,
            exhaustive_choice: false,
            policy: Policy::default(),
            metrics_listen: None,
            trusted_proxies: proxy::TrustedProxies::default(),
            advertise_url: None,
        }
    }
}

/// Shared by every handler: one `Arc`, so that the clone each extractor and layer makes per
/// request is one count, not one for each part.
#[derive(Clone)]
pub struct AppState(Arc<Shared>);

impl std::ops::Deref for AppState {
    type Target = Shared;
    fn deref(&self) -> &Shared {
        &self.0
    }
}

/// What [`AppState`] holds.
pub struct Shared {
    pub store: Store,
    pub limits: Limits,
    /// Request bodies held now, against [`Limits::inflight_bytes`] (a share per caller).
    pub bodies: Arc<Budget>,
    /// What range answers hold now, against [`Limits::answer_bytes`] (a share per caller).
    pub answers: Arc<Budget>,
    pub metrics: Arc<Metrics>,
    pub caches: Arc<ReadCaches>,
    /// Per-take motion statistics, kept for `/v1/motion-stats`.
    pub moments: Arc<crate::service::motion_stats::MomentsCache>,
    /// Takes' motion features: taken at ingest and by the index job, kept for search.
    pub index: Arc<MotionIndex>,
    pub jobs: Arc<Jobs>,
    pub streams: Arc<Streams>,
    /// Sends a live stream's requests on to the server that codes it.
    pub forwarder: Arc<forward::Forwarder>,
    /// What per-take choice has learnt from the takes ingested so far; `None` when every
    /// candidate is encoded ([`Config::exhaustive_choice`]).
    pub histories: Option<Arc<Histories>>,
    /// Who requests are, from their tokens (cached briefly).
    pub auth: Arc<Authenticator>,
    /// The audit log, with the counts of refused requests not yet written.
    pub audit: Arc<AuditLog>,
}

/// The address other servers forward a stream's requests to: `--advertise-url`, or the
/// bound address (loopback for an unspecified one: a server listening on every interface
/// of a machine shared with others should say where it is reached).
fn advertised(config: &Config, bound: SocketAddr) -> Result<String, String> {
    if let Some(url) = &config.advertise_url {
        let uri: axum::http::Uri = url
            .parse()
            .map_err(|e| format!("--advertise-url {url:?}: {e}"))?;
        if uri.scheme_str() != Some("http") || uri.host().is_none() {
            return Err(format!(
                "--advertise-url {url:?}: give http://host:port, where the other servers reach \
                 this one"
            ));
        }
        return Ok(url.trim_end_matches('/').to_string());
    }
    let ip = match bound.ip() {
        ip if ip.is_unspecified() && ip.is_ipv4() => std::net::Ipv4Addr::LOCALHOST.into(),
        ip if ip.is_unspecified() => std::net::Ipv6Addr::LOCALHOST.into(),
        ip => ip,
    };
    Ok(format!("http://{}", SocketAddr::new(ip, bound.port())))
}

/// `GET /readyz`: 200 while the database answers, else 503 with `Retry-After`.
async fn readyz(
    axum::extract::State(state): axum::extract::State<AppState>,
) -> Result<&'static str, error::ApiError> {
    crate::service::health::ready(&state.store).await?;
    Ok("ready")
}

/// The route table: every route once, with who may call it ([`routes::Access`]) and its
/// handler; each route with a body reads it through the server's `bodies` budget, under
/// its own limit.
fn declare(bodies: &Arc<Budget>, limits: &Limits) -> Routes {
    let gate = |limit: u64| {
        axum::middleware::from_fn_with_state(
            BodyGate {
                budget: bodies.clone(),
                limit,
                idle: limits.body_idle,
            },
            hold_body,
        )
    };
    let upload = gate(limits.upload_bytes);
    let append = gate(limits.append_bytes);
    let json = gate(limits.json_body_bytes);
    let json_tokens = json.clone();
    use routes::Access::{Public, Scope as Needs, Take};
    use Scope::{Admin, Read, Write};
    Routes::new()
        .get("/healthz", Public, || async { "ok" })
        .get("/readyz", Public, readyz)
        .get("/", Public, ui::index)
        .get("/ui/{*path}", Public, ui::file)
        .get("/metrics", Needs(Admin), metrics::render)
        .post(
            "/v1/takes",
            Needs(Write),
            takes::create.layer(upload.clone()),
        )
        .get("/v1/takes", Needs(Read), library::list)
        .get("/v1/takes/{id}", Take(Read), takes::get)
        .delete("/v1/takes/{id}", Take(Admin), takes::delete)
        .patch(
            "/v1/takes/{id}",
            Take(Write),
            library::patch.layer(json.clone()),
        )
        .get("/v1/takes/{id}/frames", Take(Read), takes::frames)
        .get("/v1/takes/{id}/errors", Take(Read), takes::errors)
        .get("/v1/takes/{id}/analog", Take(Read), takes::analog)
        .get("/v1/takes/{id}/outputs", Take(Read), takes::outputs)
        .get("/v1/takes/{id}/parameters", Take(Read), takes::parameters)
        .get("/v1/takes/{id}/similar", Take(Read), search::similar)
        .get("/v1/stats", Needs(Read), library::stats)
        .get("/v1/ranges", Needs(Read), takes::ranges)
        .get("/v1/export", Needs(Read), library::export)
        .get("/v1/motion-stats", Needs(Read), library::motion_stats)
        .post(
            "/v1/motion-stats",
            Needs(Read),
            library::motion_stats_of.layer(json.clone()),
        )
        .post(
            "/v1/search",
            Needs(Read),
            search::search.layer(upload.clone()),
        )
        .get("/v1/bases", Needs(Read), bases::list)
        .post("/v1/bases", Needs(Admin), bases::train.layer(json.clone()))
        .get("/v1/bases/{id}", Needs(Read), bases::get)
        .delete("/v1/bases/{id}", Needs(Admin), bases::delete)
        .get("/v1/jobs", Needs(Read), bases::jobs)
        .get("/v1/jobs/{id}", Needs(Read), bases::job)
        .get("/v1/skeletons", Needs(Read), skeletons::list)
        .post(
            "/v1/skeletons",
            Needs(Write),
            skeletons::upload.layer(upload.clone()),
        )
        .get("/v1/skeletons/{id}", Needs(Read), skeletons::get)
        .get("/v1/skeletons/{id}/map", Needs(Read), skeletons::map)
        .delete("/v1/skeletons/{id}", Needs(Admin), skeletons::delete)
        .post(
            "/v1/streams",
            Needs(Write),
            streams::open.layer(json.clone()),
        )
        .get("/v1/streams/{id}", Take(Read), streams::get)
        .get("/v1/streams/{id}/events", Take(Read), streams::events)
        .post(
            "/v1/streams/{id}/frames",
            Take(Write),
            streams::append.layer(append),
        )
        .post(
            "/v1/streams/{id}/finish",
            Take(Write),
            streams::finish.layer(json),
        )
        .get("/v1/tokens", Needs(Admin), tokens::list)
        .post(
            "/v1/tokens",
            Needs(Admin),
            tokens::create.layer(json_tokens),
        )
        .delete("/v1/tokens/{id}", Needs(Admin), tokens::revoke)
        .get("/v1/audit", Needs(Admin), tokens::audit)
}

/// Forgets the rate limiter's idle keys; run with the other maintenance.
type Forget = Arc<dyn Fn() + Send + Sync>;

/// The routes, behind authentication, scopes, rate limits, CORS and the audit log
/// ([`auth`]); with the rate limiter's key sweeper when limits are on.
pub fn router(state: AppState, policy: Policy) -> (Router, Option<Forget>) {
    let limits = state.limits;
    let (table, access) = declare(&state.bodies, &limits).finish();
    let require = axum::middleware::from_fn_with_state((state.clone(), access), routes::require);
    let inner = table
        .route_layer(require)
        .fallback(|| async {
            ApiError::new(
                StatusCode::NOT_FOUND,
                "not_found",
                "no such route; the API is described in openapi.yaml",
            )
        })
        .method_not_allowed_fallback(|| async {
            ApiError::new(
                StatusCode::METHOD_NOT_ALLOWED,
                "method_not_allowed",
                "this route does not take that method; see openapi.yaml",
            )
        })
        // The gates above have read and bounded every body already.
        .layer(DefaultBodyLimit::max(limits.upload_bytes as usize))
        .with_state(state.clone());
    let mut forget: Option<Forget> = None;
    let mut refuse = None;
    let limited = (limits.requests_per_s > 0).then(|| {
        let config = tower_governor::governor::GovernorConfigBuilder::default()
            .key_extractor(RateKey)
            .period(Duration::from_secs_f64(1.0 / limits.requests_per_s as f64))
            .burst_size(limits.request_burst.clamp(1, u64::from(u32::MAX)) as u32)
            .finish()
            .expect("a positive rate and burst");
        let limiter = config.limiter().clone();
        forget = Some(Arc::new(move || limiter.retain_recent()));
        // One limiter for both: refusals count against their address like any request.
        let layer = tower_governor::GovernorLayer::new(config).error_handler(auth::too_many);
        refuse = Some(Router::new().fallback(auth::refusal).layer(layer.clone()));
        inner.clone().layer(layer)
    });
    let cors = (!policy.allowed_origins.is_empty()).then(|| cors(&policy.allowed_origins));
    let front = Front {
        store: state.store.clone(),
        auth: state.auth.clone(),
        audit: state.audit.clone(),
        policy: Arc::new(policy),
        limited,
        refuse,
    };
    // Around the router as one service, not layered onto each route: a route layer runs
    // after routing, and sending the request on through `limited` would route it twice.
    let gated = tower::ServiceBuilder::new()
        .layer(axum::middleware::from_fn_with_state(front, auth::front))
        .service(inner);
    let router = Router::new()
        .fallback_service(gated)
        .layer(tower::util::option_layer(cors))
        // No answer is ever to be read by a browser as another type than it says.
        .layer(SetResponseHeaderLayer::if_not_present(
            axum::http::header::X_CONTENT_TYPE_OPTIONS,
            axum::http::HeaderValue::from_static("nosniff"),
        ))
        // Which API every answer speaks, so that a client can tell at its first call
        // whether it speaks the same one (the Python client does).
        .layer(SetResponseHeaderLayer::overriding(
            axum::http::HeaderName::from_static(API_HEADER),
            axum::http::HeaderValue::from_static(API_VERSION),
        ))
        .layer(SetResponseHeaderLayer::overriding(
            axum::http::HeaderName::from_static("x-mocapstore-version"),
            axum::http::HeaderValue::from_static(env!("CARGO_PKG_VERSION")),
        ))
        .layer(metrics::CountRequests(state.metrics.clone()))
        .layer(TraceLayer::new_for_http());
    (router, forget)
}

/// The header every answer names the API's version in.
pub const API_HEADER: &str = "x-mocapstore-api";

/// The API's version: its major number, raised when a client of the previous one would
/// misread an answer (fields or headers removed or changed in meaning); additions keep it.
pub const API_VERSION: &str = "1";

/// CORS for the allowed origins: the methods and headers the API takes, and the headers of
/// its answers a page may read.
fn cors(origins: &[String]) -> tower_http::cors::CorsLayer {
    use axum::http::{header, HeaderName, HeaderValue, Method};
    let origins: Vec<HeaderValue> = origins
        .iter()
        .filter_map(|o| HeaderValue::from_str(o).ok())
        .collect();
    let mut allow = vec![header::AUTHORIZATION, header::CONTENT_TYPE];
    for (f, _) in takes::HEADER_FIELDS {
        allow.push(HeaderName::from_bytes(format!("x-mocap-{f}").as_bytes()).expect("ASCII"));
    }
    let expose: Vec<HeaderName> = ["x-frames", "x-points", "x-start-frame", "x-fps", API_HEADER]
        .iter()
        .map(|h| HeaderName::from_static(h))
        .chain([header::LOCATION, header::RETRY_AFTER])
        .collect();
    tower_http::cors::CorsLayer::new()
        .allow_origin(origins)
        .allow_methods([Method::GET, Method::POST, Method::PATCH, Method::DELETE])
        .allow_headers(allow)
        .expose_headers(expose)
        .max_age(Duration::from_secs(3600))
}

/// A bound, ready-to-serve service.
pub struct Application {
    listener: TcpListener,
    /// `--metrics-listen`'s listener, if asked for.
    metrics_listener: Option<TcpListener>,
    router: Router,
    store: Store,
    state: AppState,
    forget_idle_keys: Option<Forget>,
    proxies: Arc<proxy::TrustedProxies>,
}

impl Application {
    /// Open the store named by the config (migrating it), bind, and get ready to serve.
    pub async fn build(config: Config) -> Result<Application, String> {
        let store = Store::open(&config.database_url)
            .await
            .map_err(|e| format!("{}: {e}", config.database_url))?;
        Application::with_store(store, config).await
    }

    /// As [`Application::build`], on a store that is already open.
    pub async fn with_store(store: Store, config: Config) -> Result<Application, String> {
        let listener = TcpListener::bind(&config.listen)
            .await
            .map_err(|e| format!("cannot listen on {}: {e}", config.listen))?;
        let metrics_listener = match &config.metrics_listen {
            None => None,
            Some(addr) => Some(
                TcpListener::bind(addr)
                    .await
                    .map_err(|e| format!("cannot listen on {addr} (--metrics-listen): {e}"))?,
            ),
        };
        let limits = config.limits;
        let bound = listener
            .local_addr()
            .map_err(|e| format!("{}: {e}", config.listen))?;
        let node = Node::new(advertised(&config, bound)?);
        let answers = Arc::new(Budget::new(limits.answer_bytes, limits.answer_share_bytes));
        let caches = Arc::new(ReadCaches::new(config.decoded_cache_mib << 20));
        let state = AppState(Arc::new(Shared {
            store: store.clone(),
            limits,
            bodies: Arc::new(Budget::new(limits.inflight_bytes, limits.body_share_bytes)),
            index: Arc::new(MotionIndex::new(
                store.clone(),
                caches.clone(),
                answers.clone(),
                limits,
            )),
            answers,
            metrics: Arc::new(Metrics::default()),
            caches,
            moments: Default::default(),
            jobs: Arc::new(Jobs::new(store.clone(), config.job_lease, &node.id)),
            streams: Arc::new(Streams::new(limits, config.stream_lease, node.clone())),
            forwarder: Arc::new(forward::Forwarder::new(&node.id)),
            histories: (!config.exhaustive_choice).then(|| Arc::new(Histories::default())),
            auth: Arc::new(Authenticator::default()),
            audit: Arc::new(AuditLog::default()),
        }));
        // Without tokens the server answers anyone who reaches it: only loopback, unless
        // the operator says otherwise.
        let addr = bound;
        if !addr.ip().is_loopback() {
            let tokens = state
                .auth
                .required(&store)
                .await
                .map_err(|e| format!("reading tokens: {e}"))?;
            if !tokens && !config.policy.open_beyond_loopback {
                return Err(format!(
                    "refusing to serve {addr} without tokens: anyone who reaches it could read, \
                     change and delete the archive. Create one first (mocapstore token create \
                     --scope admin --name NAME), or listen on 127.0.0.1, or pass \
                     --insecure-no-auth"
                ));
            }
            if !tokens {
                tracing::warn!(
                    %addr,
                    "serving WITHOUT authentication beyond loopback (--insecure-no-auth): \
                     anyone who reaches this address can read, change and delete the archive"
                );
            }
        }
        // Takes left live by a server that died mid-stream are closed before serving.
        state
            .streams
            .close_orphans(&state.store)
            .await
            .map_err(|e| format!("closing interrupted streams: {e}"))?;
        let (router, forget_idle_keys) = router(state.clone(), config.policy);
        Ok(Application {
            listener,
            metrics_listener,
            router,
            store,
            state,
            forget_idle_keys,
            proxies: Arc::new(config.trusted_proxies.clone()),
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.listener
            .local_addr()
            .expect("a bound listener has an address")
    }

    /// The address `/metrics` is served on without a token, if one was asked for.
    pub fn metrics_addr(&self) -> Option<SocketAddr> {
        self.metrics_listener
            .as_ref()
            .and_then(|l| l.local_addr().ok())
    }

    /// Serve until `shutdown` resolves; in-flight requests finish, then the pool closes.
    pub async fn run_until(
        self,
        shutdown: impl std::future::Future<Output = ()> + Send + 'static,
    ) -> std::io::Result<()> {
        // Stream leases, idle streams and orphaned live takes, in the background.
        let state = self.state.clone();
        let forget = self.forget_idle_keys.clone();
        let reaper = tokio::spawn(async move {
            // Leases renewed three times a lease at least: a quiet stream's server that lives
            // is never taken for stopped.
            let every = (state.streams.lease / 3).clamp(Duration::from_secs(1), MAINTENANCE_PERIOD);
            let mut tick = tokio::time::interval(every);
            let mut pruned: Option<std::time::Instant> = None;
            loop {
                tick.tick().await;
                state.streams.maintain(&state.store).await;
                if let Some(f) = &forget {
                    f();
                }
                if let Err(e) = state.audit.flush(&state.store, false).await {
                    tracing::warn!(error = %e, "writing the counts of refused requests failed");
                }
                // Old audit entries go once a minute (a DELETE by the indexed time).
                if pruned.is_none_or(|t| t.elapsed() >= Duration::from_secs(60)) {
                    pruned = Some(std::time::Instant::now());
                    let retention = state.limits.audit_retention;
                    if let Err(e) = AuditLog::prune(&state.store, retention).await {
                        tracing::warn!(error = %e, "deleting old audit entries failed");
                    }
                }
            }
        });
        // Jobs whose server died, taken over (a third of a lease after it ran out at most);
        // finished ones forgotten after a week.
        let state = self.state.clone();
        let job_watch = tokio::spawn(async move {
            let every = (state.jobs.lease() / 3).max(Duration::from_millis(200));
            let mut tick = tokio::time::interval(every);
            let mut pruned: Option<std::time::Instant> = None;
            let mut indexed: Option<std::time::Instant> = None;
            loop {
                tick.tick().await;
                loop {
                    match crate::service::background::take_over(&state.index, &state.jobs).await {
                        Ok(true) => continue,
                        Ok(false) => break,
                        Err(e) => {
                            tracing::warn!(error = %e, "looking for jobs to take over failed");
                            break;
                        }
                    }
                }
                // Takes whose motion features are missing or stale (stored before features
                // were, re-encoded, finished streaming, given another body): the index job
                // takes them, on one server at a time.
                if indexed.is_none_or(|t| t.elapsed() >= INDEX_PERIOD) {
                    indexed = Some(std::time::Instant::now());
                    let started =
                        crate::service::motion_index::start_if_stale(&state.index, &state.jobs);
                    if let Err(e) = started.await {
                        tracing::warn!(error = %e, "starting the motion index job failed");
                    }
                }
                if pruned.is_none_or(|t| t.elapsed() >= Duration::from_secs(3600)) {
                    pruned = Some(std::time::Instant::now());
                    if let Err(e) = state.jobs.prune().await {
                        tracing::warn!(error = %e, "forgetting old jobs failed");
                    }
                }
            }
        });
        // Watches of live streams never end on their own: end them first, or the graceful
        // shutdown would wait for them.
        let streams = self.state.streams.clone();
        let (stopping, stopped) = tokio::sync::watch::channel(false);
        let shutdown = async move {
            shutdown.await;
            streams.stop_watchers();
            stopping.send_replace(true);
        };
        let metrics = self.metrics_listener.map(|l| {
            let router = Router::new()
                .route("/metrics", get(metrics::render))
                .with_state(self.state.clone());
            let mut stopped = stopped.clone();
            // A scraper or two: a few connections, within the file budget the defaults keep.
            let limits = Limits {
                connections: METRICS_CONNECTIONS,
                connections_per_address: METRICS_CONNECTIONS,
                ..self.state.limits
            };
            let m = self.state.metrics.clone();
            let none = Arc::new(proxy::TrustedProxies::default());
            tokio::spawn(serve::serve(l, router, limits, m, none, async move {
                let _ = stopped.wait_for(|s| *s).await;
            }))
        });
        let served = serve::serve(
            self.listener,
            self.router,
            self.state.limits,
            self.state.metrics.clone(),
            self.proxies,
            shutdown,
        )
        .await;
        reaper.abort();
        job_watch.abort();
        if let Some(m) = metrics {
            let _ = m.await;
        }
        drop(stopped);
        if let Err(e) = self.state.audit.flush(&self.state.store, true).await {
            tracing::warn!(error = %e, "writing the counts of refused requests failed");
        }
        served?;
        self.store.close().await;
        Ok(())
    }
}

/// Resolves on Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        if let Ok(mut s) = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        {
            s.recv().await;
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = term => {},
    }
}

/// Entry points for the fuzz targets (`fuzz/`): every parser of request input, on raw bytes,
/// with no server, store or runtime. Not an API.
#[doc(hidden)]
pub mod fuzz {
    use axum::body::Bytes;
    use axum::extract::Query;
    use axum::http::{header, HeaderMap, HeaderValue, Uri};

    use crate::limits::Limits;

    /// `data` is a query string, a NUL, then a body: each query parser reads the query,
    /// each body parser the body (as JSON and as f32 frames), and the ingest request takes
    /// both, with the query's values also offered as `x-mocap-*` headers.
    pub fn requests(data: &[u8]) {
        let split = data.iter().position(|b| *b == 0).unwrap_or(data.len());
        let (query, body) = (&data[..split], data.get(split + 1..).unwrap_or(&[]));
        let query = String::from_utf8_lossy(query);
        let body = Bytes::copy_from_slice(body);
        let Ok(uri) = format!("/?{query}").parse::<Uri>() else {
            return;
        };
        let mut headers = HeaderMap::new();
        for (k, v) in query.split('&').filter_map(|kv| kv.split_once('=')) {
            if let (Ok(name), Ok(value)) = (
                format!("x-mocap-{}", k.replace('_', "-")).parse::<header::HeaderName>(),
                HeaderValue::from_str(v),
            ) {
                headers.insert(name, value);
            }
        }
        if let Ok(Query(q)) = Query::<super::takes::IngestQuery>::try_from_uri(&uri) {
            let _ = super::takes::ingest_request(q, &headers, body.clone(), &Limits::default());
        }
        if let Ok(Query(q)) = Query::<super::takes::FramesQuery>::try_from_uri(&uri) {
            let _ = super::takes::frames_request(q);
        }
        let _ = Query::<super::library::PageQuery>::try_from_uri(&uri);
        if let Ok(Query(q)) = Query::<crate::service::library::TakeQuery>::try_from_uri(&uri) {
            let pairs = Query::<Vec<(String, String)>>::try_from_uri(&uri)
                .map(|Query(p)| p)
                .unwrap_or_default();
            let q = q.with_labels(pairs.iter().map(|(k, v)| (k.as_str(), v.as_str())));
            let _ = q.check();
        }
        // Labels as a query, a file-name pattern and a name, and as JSON (PATCH, sidecars).
        let _ = crate::labels::Labels::parse(&query);
        if let Some((pattern, name)) = query.split_once('&') {
            if let Ok(p) = crate::labels::NamePattern::parse(pattern) {
                let _ = p.labels(name);
            }
        }
        if let Ok(v) = serde_json::from_slice::<serde_json::Value>(&body) {
            let _ = crate::labels::Labels::from_json(&v);
            if let Ok(c) = crate::labels::LabelChanges::from_json(&v) {
                let _ = c.apply(&crate::labels::Labels::new());
            }
        }
        let _ = crate::store::Cursor::decode(&query);
        let mut json = HeaderMap::new();
        json.insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/json"),
        );
        let _ = super::streams::parse_frames(&json, &body);
        let _ = super::streams::parse_frames(&HeaderMap::new(), &body);
        let _ = serde_json::from_slice::<crate::service::streams::OpenRequest>(&body);
        let _ = serde_json::from_slice::<crate::service::training::TrainRequest>(&body);
        let _ = serde_json::from_slice::<super::library::Patch>(&body);
    }
}
