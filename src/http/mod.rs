//! The HTTP API (axum): routers, extractors, errors to responses. No math, no SQL.
//!
//! [`Application::build`] binds the listener first, so it knows its port before serving:
//! tests start the real server on `127.0.0.1:0` and read the port back.

mod bases;
mod error;
mod library;
mod metrics;
mod sequences;
mod streams;

use std::net::SocketAddr;
use std::sync::Arc;

use axum::extract::DefaultBodyLimit;
use axum::routing::get;
use axum::Router;
use tokio::net::TcpListener;
use tower_http::trace::TraceLayer;

pub use error::ApiError;
pub use metrics::Metrics;

use crate::motion::formats::Limits;
use crate::service::jobs::Jobs;
use crate::service::prepared::ReadCaches;
use crate::service::streams::Streams;
use crate::store::Store;

/// How to run the service.
#[derive(Debug, Clone)]
pub struct Config {
    pub listen: String,
    pub database_url: String,
    /// Largest upload accepted; larger bodies get 413.
    pub max_body_bytes: usize,
    /// Memory for decoded chunks kept between range requests, MiB.
    pub decoded_cache_mib: usize,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            listen: "127.0.0.1:8080".into(),
            database_url: "sqlite://mocapstore.db".into(),
            max_body_bytes: 512 << 20,
            decoded_cache_mib: 256,
        }
    }
}

/// Shared by every handler.
#[derive(Clone)]
pub struct AppState {
    pub store: Store,
    pub limits: Limits,
    pub metrics: Arc<Metrics>,
    pub caches: Arc<ReadCaches>,
    pub jobs: Arc<Jobs>,
    pub streams: Arc<Streams>,
}

pub fn router(state: AppState, max_body_bytes: usize) -> Router {
    Router::new()
        .route("/healthz", get(|| async { "ok" }))
        .route("/metrics", get(metrics::render))
        .route(
            "/v1/sequences",
            axum::routing::post(sequences::create).get(library::list),
        )
        .route(
            "/v1/sequences/{id}",
            get(sequences::get)
                .delete(sequences::delete)
                .patch(library::patch),
        )
        .route("/v1/stats", get(library::stats))
        .route("/v1/bases", get(bases::list).post(bases::train))
        .route("/v1/bases/{id}", get(bases::get).delete(bases::delete))
        .route("/v1/jobs/{id}", get(bases::job))
        .route("/v1/streams", axum::routing::post(streams::open))
        .route("/v1/streams/{id}", get(streams::get))
        .route(
            "/v1/streams/{id}/frames",
            axum::routing::post(streams::append),
        )
        .route(
            "/v1/streams/{id}/finish",
            axum::routing::post(streams::finish),
        )
        .route("/v1/sequences/{id}/frames", get(sequences::frames))
        .layer(DefaultBodyLimit::max(max_body_bytes))
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
        let limits = Limits {
            max_bytes: config.max_body_bytes as u64,
            ..Limits::default()
        };
        let state = AppState {
            store: store.clone(),
            limits,
            metrics: Arc::new(Metrics::default()),
            caches: Arc::new(ReadCaches::new(config.decoded_cache_mib << 20)),
            jobs: Arc::new(Jobs::default()),
            streams: Arc::new(Streams::default()),
        };
        Ok(Application {
            listener,
            router: router(state.clone(), config.max_body_bytes),
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
        // Streams nobody writes to any more are finished in the background.
        let state = self.state.clone();
        let reaper = tokio::spawn(async move {
            let mut tick = tokio::time::interval(std::time::Duration::from_secs(30));
            loop {
                tick.tick().await;
                state.streams.reap_idle(&state.store, &state.caches).await;
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
