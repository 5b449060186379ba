//! The connection loop: what `axum::serve` does, plus the limits it does not offer. Every connection is HTTP/1.1
//! on hyper with a timer, so a client that opens a socket and sends no complete header within
//! `--header-read-timeout-s` is dropped (also between requests on a kept-alive connection); at most
//! `--max-connections` are served at once, and one more is answered 503 `too-many-connections` and closed at
//! once, so idle sockets cannot exhaust the process's file descriptors; each request carries the client's
//! address (`ConnectInfo`) for the per-address throttling of failed API keys. Request bodies get the pause limit
//! of `--body-read-timeout-s` in the router (`routes::router`).

use super::AppState;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use std::future::Future;
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};

/// Serves `app` on `listener` until `shutdown` completes; then stops accepting, lets open connections finish
/// their requests for at most `grace`, and returns.
pub async fn serve(
    listener: TcpListener,
    app: axum::Router,
    state: AppState,
    shutdown: impl Future<Output = ()>,
    grace: Duration,
) {
    let config = &state.config;
    let permits = Arc::new(tokio::sync::Semaphore::new(config.max_connections.max(1)));
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(Duration::from_secs_f64(config.header_read_timeout_s.max(0.001)))
        .keep_alive(true);
    let graceful = GracefulShutdown::new();
    tokio::pin!(shutdown);
    loop {
        let (stream, remote) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(c) => c,
                Err(e) => {
                    // Out of file descriptors (or a like transient error): back off instead of spinning.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let Ok(permit) = permits.clone().try_acquire_owned() else {
            state.metrics.connections_refused.fetch_add(1, Ordering::Relaxed);
            tokio::spawn(refuse(stream, config.max_connections));
            continue;
        };
        let app = tower::ServiceExt::map_request(app.clone(), move |mut req: axum::http::Request<Incoming>| {
            req.extensions_mut().insert(ConnectInfo(remote));
            req
        });
        let conn = http.serve_connection(TokioIo::new(stream), TowerToHyperService::new(app));
        let conn = graceful.watch(conn);
        let st = state.clone();
        st.metrics.connections_open.fetch_add(1, Ordering::Relaxed);
        tokio::spawn(async move {
            let _ = conn.await;
            st.metrics.connections_open.fetch_sub(1, Ordering::Relaxed);
            drop(permit);
        });
    }
    drop(listener);
    if tokio::time::timeout(grace, graceful.shutdown()).await.is_err() {
        tracing::warn!("connections still open after the grace period are dropped");
    }
}

/// Answers one connection over the limit with its problem (`too-many-connections`, the status its code maps to) and
/// closes it.
async fn refuse(mut stream: TcpStream, limit: usize) {
    let code = kac_engine::Code::TooManyConnections;
    let problem = super::problem::Problem::new(
        code,
        "Too many connections",
        format!("the server holds its limit of {limit} open connections (--max-connections); retry shortly"),
    );
    let body = serde_json::to_string(&problem).unwrap_or_default();
    let status = super::error::status_of(code);
    let head = format!(
        "HTTP/1.1 {} {}\r\ncontent-type: application/problem+json\r\nretry-after: 1\r\n\
         connection: close\r\ncontent-length: {}\r\n\r\n",
        status.as_u16(),
        status.canonical_reason().unwrap_or(""),
        body.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), async {
        let _ = stream.write_all(head.as_bytes()).await;
        let _ = stream.write_all(body.as_bytes()).await;
        let _ = stream.shutdown().await;
    })
    .await;
}

/// The client's address of a request (set by [`serve`]; absent when the router runs without this loop).
pub fn client_addr(req: &axum::extract::Request) -> Option<SocketAddr> {
    req.extensions().get::<ConnectInfo<SocketAddr>>().map(|c| c.0)
}
