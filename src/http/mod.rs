//! The HTTP API (axum): routers, extractors, errors to responses. No math, no SQL.
//!
//! [`Application::build`] binds the listener first, so it knows its port before serving:
//! tests start the real server on `127.0.0.1:0` and read the port back.

mod bases;
pub mod budget;
mod error;
mod library;
mod metrics;
mod sequences;
mod skeletons;
mod streams;
mod views;

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::DefaultBodyLimit;
use axum::handler::Handler;
use axum::http::StatusCode;
use axum::routing::{get, post};
use axum::Router;
use tokio::net::TcpListener;
use tower_http::trace::TraceLayer;

use budget::{hold_body, BodyBudget, BodyGate};
pub use error::ApiError;
pub use metrics::Metrics;

use crate::limits::Limits;
use crate::service::history::Histories;
use crate::service::jobs::Jobs;
use crate::service::prepared::ReadCaches;
use crate::service::streams::Streams;
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
    /// Encode every candidate of every take in full: no candidate is left out by what a
    /// layout's earlier takes say ([`crate::service::history`]).
    pub exhaustive_choice: bool,
}

/// How often the server renews its streams' leases, finishes idle streams and closes the
/// takes of streams whose server died.
pub const MAINTENANCE_PERIOD: Duration = Duration::from_secs(10);

impl Default for Config {
    fn default() -> Self {
        Config {
            listen: "127.0.0.1:8080".into(),
            database_url: "sqlite://mocapstore.db".into(),
            limits: Limits::default(),
            decoded_cache_mib: 256,
            stream_lease: Duration::from_secs(60),
            exhaustive_choice: false,
        }
    }
}

/// Shared by every handler.
#[derive(Clone)]
pub struct AppState {
    pub store: Store,
    pub limits: Limits,
    /// Request bodies held now, against [`Limits::inflight_bytes`].
    pub bodies: Arc<BodyBudget>,
    pub metrics: Arc<Metrics>,
    pub caches: Arc<ReadCaches>,
    pub jobs: Arc<Jobs>,
    pub streams: Arc<Streams>,
    /// What per-take choice has learnt from the takes ingested so far; `None` when every
    /// candidate is encoded ([`Config::exhaustive_choice`]).
    pub histories: Option<Arc<Histories>>,
}

pub fn router(state: AppState) -> Router {
    let limits = state.limits;
    // Each route with a body reads it through the server's budget, under its own limit.
    let gate = |limit: u64| {
        axum::middleware::from_fn_with_state(
            BodyGate {
                budget: state.bodies.clone(),
                limit,
            },
            hold_body,
        )
    };
    let upload = gate(limits.upload_bytes);
    let append = gate(limits.append_bytes);
    let json = gate(limits.json_body_bytes);
    Router::new()
        .route("/healthz", get(|| async { "ok" }))
        .route("/metrics", get(metrics::render))
        .route(
            "/v1/sequences",
            post(sequences::create.layer(upload)).get(library::list),
        )
        .route(
            "/v1/sequences/{id}",
            get(sequences::get)
                .delete(sequences::delete)
                .patch(library::patch.layer(json.clone())),
        )
        .route("/v1/stats", get(library::stats))
        .route(
            "/v1/bases",
            get(bases::list).post(bases::train.layer(json.clone())),
        )
        .route("/v1/bases/{id}", get(bases::get).delete(bases::delete))
        .route("/v1/jobs/{id}", get(bases::job))
        .route("/v1/skeletons", get(skeletons::list))
        .route(
            "/v1/skeletons/{id}",
            get(skeletons::get).delete(skeletons::delete),
        )
        .route("/v1/streams", post(streams::open.layer(json.clone())))
        .route("/v1/streams/{id}", get(streams::get))
        .route(
            "/v1/streams/{id}/frames",
            post(streams::append.layer(append)),
        )
        .route("/v1/streams/{id}/finish", post(streams::finish.layer(json)))
        .route("/v1/sequences/{id}/frames", get(sequences::frames))
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
        .layer(axum::middleware::from_fn_with_state(
            state.metrics.clone(),
            metrics::count_requests,
        ))
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

/// A bound, ready-to-serve service.
pub struct Application {
    listener: TcpListener,
    router: Router,
    store: Store,
    state: AppState,
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
        let limits = config.limits;
        let state = AppState {
            store: store.clone(),
            limits,
            bodies: Arc::new(BodyBudget::new(limits.inflight_bytes)),
            metrics: Arc::new(Metrics::default()),
            caches: Arc::new(ReadCaches::new(config.decoded_cache_mib << 20)),
            jobs: Arc::new(Jobs::default()),
            streams: Arc::new(Streams::new(limits, config.stream_lease)),
            histories: (!config.exhaustive_choice).then(|| Arc::new(Histories::default())),
        };
        // Takes left live by a server that died mid-stream are closed before serving.
        state
            .streams
            .close_orphans(&state.store, &state.caches)
            .await
            .map_err(|e| format!("closing interrupted streams: {e}"))?;
        Ok(Application {
            listener,
            router: router(state.clone()),
            store,
            state,
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.listener
            .local_addr()
            .expect("a bound listener has an address")
    }

    /// Serve until `shutdown` resolves; in-flight requests finish, then the pool closes.
    pub async fn run_until(
        self,
        shutdown: impl std::future::Future<Output = ()> + Send + 'static,
    ) -> std::io::Result<()> {
        // Stream leases, idle streams and orphaned live takes, in the background.
        let state = self.state.clone();
        let reaper = tokio::spawn(async move {
            let mut tick = tokio::time::interval(MAINTENANCE_PERIOD);
            loop {
                tick.tick().await;
                state.streams.maintain(&state.store, &state.caches).await;
            }
        });
        let served = axum::serve(self.listener, self.router)
            .with_graceful_shutdown(shutdown)
            .await;
        reaper.abort();
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
        if let Ok(Query(q)) = Query::<super::sequences::IngestQuery>::try_from_uri(&uri) {
            let _ = super::sequences::ingest_request(q, &headers, body.clone(), &Limits::default());
        }
        if let Ok(Query(q)) = Query::<super::sequences::FramesQuery>::try_from_uri(&uri) {
            let _ = super::sequences::frames_request(q);
        }
        let _ = Query::<super::library::ListQuery>::try_from_uri(&uri);
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
