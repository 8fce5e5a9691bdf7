//! The accept loop: HTTP/1.1 connections with a header-read timeout (also the keep-alive idle
//! limit: hyper starts the clock whenever a connection waits for a request's head), a cap on open
//! connections (further ones are closed at once), and graceful shutdown (no new connections once
//! `shutdown` resolves; the future ends when every open connection has).

use axum::Router;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tracing::{debug, warn};

/// Pending connections the kernel queues for `accept` (the listen backlog). Tokio's
/// `TcpListener::bind` asks for 128, as the standard library does: a burst of new connections
/// while the accept loop is busy then overflows it, and each dropped SYN costs its client a
/// one-second retransmit. (The kernel caps it at `net.core.somaxconn`.)
pub const LISTEN_BACKLOG: u32 = 4096;

/// Binds the service's listening socket on `addr` with [`LISTEN_BACKLOG`].
pub async fn bind(addr: &str) -> std::io::Result<TcpListener> {
    let mut last = None;
    for a in tokio::net::lookup_host(addr).await? {
        let socket = if a.is_ipv4() {
            tokio::net::TcpSocket::new_v4()?
        } else {
            tokio::net::TcpSocket::new_v6()?
        };
        socket.set_reuseaddr(true)?;
        match socket.bind(a).and_then(|()| socket.listen(LISTEN_BACKLOG)) {
            Ok(l) => return Ok(l),
            Err(e) => last = Some(e),
        }
    }
    Err(last.unwrap_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "address resolved to nothing",
        )
    }))
}

/// Per-connection limits, from `[server]`.
#[derive(Clone, Copy, Debug)]
pub(super) struct ConnLimits {
    /// Open connections at most (at least 1).
    pub max_connections: usize,
    /// Time to send a request's headers, and to start the next request on a kept-alive connection.
    pub header_read_timeout: Duration,
}

/// Serves `app` on `listener` until `shutdown` resolves and every connection has closed.
pub(super) async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnLimits,
    shutdown: impl Future<Output = ()>,
) {
    let open = Arc::new(Semaphore::new(limits.max_connections.max(1)));
    let graceful = GracefulShutdown::new();
    tokio::pin!(shutdown);
    loop {
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(conn) => conn,
                Err(e) => {
                    // Out of file descriptors and the like: back off instead of spinning.
                    warn!(error = %e, "accepting a connection failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let Ok(permit) = open.clone().try_acquire_owned() else {
            debug!(%peer, "connection refused: server.max_connections are open");
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let conn = http1::Builder::new()
            .timer(TokioTimer::new())
            .header_read_timeout(limits.header_read_timeout)
            .serve_connection(TokioIo::new(stream), TowerToHyperService::new(app.clone()));
        let conn = graceful.watch(conn);
        tokio::spawn(async move {
            let _permit = permit;
            if let Err(e) = conn.await {
                debug!(%peer, error = %e, "connection ended with an error");
            }
        });
    }
    drop(listener);
    graceful.shutdown().await;
}
