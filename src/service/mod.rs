//! `kac serve`: the HTTP service, a thin layer over `kac_core` and [`crate::analysis`]. Shapes are uploaded and
//! addressed by content hash; analyses run as jobs on a rayon pool behind a bounded queue; results are immutable
//! JSON (and `.npy` / coloured PLY per array) with strong ETags; every error is RFC 9457 problem+json.

pub mod bodies;
pub mod config;
pub mod error;
pub mod ids;
pub mod listener;
pub mod openapi;
pub mod ops;
pub mod problem;
pub mod routes;
pub mod strict;

pub use kac_engine::{compare, correspondence, faults, jobs, limits, search, store};

use config::Config;
use kac_engine::Engine;
use std::sync::Arc;

/// The HTTP layer's state: the engine it drives, and what only HTTP has (the flags of `kac serve`, the metrics of
/// requests, API keys and rate limits, the memory of bodies in flight). Reads through to the engine's fields.
pub struct Inner {
    pub engine: Arc<Engine>,
    pub config: Config,
    pub metrics: Arc<ops::Metrics>,
    pub access: ops::Access,
    /// The memory request bodies in flight hold together.
    pub bodies: bodies::BodyBudget,
}

impl std::ops::Deref for Inner {
    type Target = Engine;
    fn deref(&self) -> &Engine {
        &self.engine
    }
}

pub type AppState = Arc<Inner>;

impl Inner {
    /// Checks the configuration (fail closed: before any store is opened), then opens the engine.
    pub fn new(config: Config) -> std::io::Result<AppState> {
        let invalid = |e: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, e);
        config.check().map_err(invalid)?;
        let keys = config.api_keys().map_err(invalid)?;
        let metrics = Arc::new(ops::Metrics::default());
        let engine = Engine::open(config.engine.clone(), metrics.clone(), |c| error::status_of(c).as_u16())?;
        Ok(Arc::new(Inner {
            engine,
            metrics,
            bodies: bodies::BodyBudget::new(config.max_body_memory_bytes),
            access: ops::Access::new(&keys, config.rate_limit_per_minute, config.auth_failures_per_minute),
            config,
        }))
    }
}

/// Starts the server and runs until SIGINT or SIGTERM; prints `{"listening": "ADDR"}` on stdout first.
pub fn serve(config: Config) -> Result<(), String> {
    init_logging();
    // Checked before the port is bound: a server that would run open or with a broken limit never listens.
    config.check().map_err(|e| format!("the configuration is refused: {e}"))?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the runtime: {e}"))?;
    rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(&config.addr)
            .await
            .map_err(|e| format!("cannot listen on {}: {e}", config.addr))?;
        let addr = listener.local_addr().map_err(|e| e.to_string())?;
        let state = Inner::new(config).map_err(|e| match e.kind() {
            std::io::ErrorKind::InvalidInput => format!("the configuration is refused: {e}"),
            _ => format!("cannot open the store: {e}"),
        })?;
        let recovered = state.recovered;
        let app = routes::router(state.clone());
        println!("{}", serde_json::json!({ "listening": addr.to_string(), "recovered_jobs": recovered }));
        use std::io::Write;
        let _ = std::io::stdout().flush();
        let st = state.clone();
        let grace = std::time::Duration::from_secs(state.config.shutdown_grace_s);
        // One grace period from the signal, shared by open connections and running jobs.
        let signalled = Arc::new(std::sync::OnceLock::<std::time::Instant>::new());
        let at = signalled.clone();
        let shutdown = async move {
            shutdown_signal().await;
            let _ = at.set(std::time::Instant::now());
            tracing::info!("shutting down: no new connections, no new jobs");
            st.draining.store(true, std::sync::atomic::Ordering::SeqCst);
        };
        listener::serve(listener, app, state.clone(), shutdown, grace).await;
        // Let running jobs finish within what is left of the grace period; enqueued ones stay in the store for the
        // next start.
        let deadline = *signalled.get_or_init(std::time::Instant::now) + grace;
        while state.jobs.running() > 0 && std::time::Instant::now() < deadline {
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        }
        // The next start reads the index from its snapshot instead of the whole store.
        if let Err(e) = state.index.persist(&*state.fingerprints) {
            tracing::warn!(error = %e, "the search index snapshot could not be written");
        }
        tracing::info!(running = state.jobs.running(), "stopped");
        Ok(())
    })
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}

/// Structured JSON logs on stderr; `RUST_LOG` filters (default `info`).
fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into());
    let _ = tracing_subscriber::fmt().json().with_env_filter(filter).with_writer(std::io::stderr).try_init();
    // A panic (caught per job) is one structured log line, not a backtrace on stderr.
    std::panic::set_hook(Box::new(|info| {
        let thread = std::thread::current().name().unwrap_or("unnamed").to_string();
        tracing::error!(thread = %thread, panic = %info, "panic");
    }));
}
