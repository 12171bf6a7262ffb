//! Connections: the accept loop and what bounds each connection, so that idle or slow
//! clients cannot take the server's sockets or file descriptors.
//!
//! - **A cap** on connections open at once ([`Limits::connections`]) and per client address
//!   ([`Limits::connections_per_address`]). Past either, a new connection is answered
//!   `503` with `Retry-After` and the one error shape, and closed; at most
//!   [`REFUSING_AT_ONCE`] refusals are written at a time, and past that a connection is
//!   closed unanswered. The defaults fit a process allowed 1,024 files.
//! - **A header timeout** ([`Limits::header_timeout`]): a client has that long to send a
//!   request's headers, counted from the connection's start or from the first byte of a
//!   request that follows another.
//! - **An idle timeout** ([`Limits::idle_timeout`]): a connection with no request in
//!   progress and nothing arriving is closed.
//! - **A send timeout** ([`Limits::send_timeout`]): a connection whose client reads nothing
//!   of an answer for that long is closed (its answer's memory freed).
//!
//! A body that stops arriving is the body gate's to time out ([`super::budget`], 408),
//! since only it knows that a request is waiting for one. Addresses are counted as
//! [`Holder::address`] counts them (an IPv6 client by its /64).
//!
//! HTTP/1.1 only. HTTP/2 over plain TCP (prior knowledge) is spoken by no browser and few
//! clients; its streams would let one connection hold many answers past the connection cap,
//! and its flow control can stall an answer where the socket never blocks, out of the send
//! timeout's sight. A TLS-terminating proxy speaks HTTP/2 to clients and HTTP/1.1 here.
//!
//! Why not `axum::serve`: it sets no timer, so hyper applies none of these, and it has no
//! cap: 1,100 idle sockets exhausted a 1,024-file limit (`accept error: Too many open
//! files`) and valid requests timed out.

use std::convert::Infallible;
use std::future::Future;
use std::io;
use std::net::{IpAddr, SocketAddr};
use std::pin::{pin, Pin};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::body::{Body, HttpBody};

use super::proxy::TrustedProxies;
use axum::extract::ConnectInfo;
use axum::http::{Request, Response};
use axum::Router;
use hyper::body::Incoming;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tower::Service;

use super::metrics::Metrics;
use crate::limits::{Limits, RETRY_AFTER_S};
use crate::service::budget::{Holder, Share, Shares};

/// Refusals (503s to connections past the cap) written at once; past it a connection is
/// closed unanswered, so that refusing cannot itself hold many sockets.
pub const REFUSING_AT_ONCE: usize = 64;

/// Why a connection was closed by the server.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Closed {
    Header,
    Idle,
    Send,
}

impl Closed {
    pub fn name(self) -> &'static str {
        match self {
            Closed::Header => "header_timeout",
            Closed::Idle => "idle_timeout",
            Closed::Send => "send_timeout",
        }
    }
}

/// Accept connections on `listener` and serve `router` on each until `shutdown` resolves;
/// then stop accepting and let the open connections finish what they are doing.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    limits: Limits,
    metrics: Arc<Metrics>,
    proxies: Arc<TrustedProxies>,
    shutdown: impl Future<Output = ()> + Send,
) -> io::Result<()> {
    let gate = Gate {
        slots: Arc::new(Semaphore::new(limits.connections.max(1) as usize)),
        per_address: Shares::new(limits.connections_per_address as usize),
    };
    let refusing = Arc::new(Semaphore::new(REFUSING_AT_ONCE));
    let graceful = GracefulShutdown::new();
    let mut shutdown = pin!(shutdown);
    let mut last_accept_error: Option<Instant> = None;
    loop {
        let accepted = tokio::select! {
            r = listener.accept() => r,
            () = &mut shutdown => break,
        };
        let (stream, peer) = match accepted {
            Ok(a) => a,
            Err(e) => {
                // Out of file descriptors (or another passing failure): say so at most once
                // a second, and give the connections that hold them time to end.
                if last_accept_error.is_none_or(|t| t.elapsed() > Duration::from_secs(1)) {
                    tracing::warn!(error = %e, "accept failed");
                    last_accept_error = Some(Instant::now());
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        let slot = match gate.admit(peer.ip(), proxies.contains(peer.ip())) {
            Ok(s) => s,
            Err(why) => {
                metrics.connection_refused();
                refuse(stream, &refusing, why);
                continue;
            }
        };
        metrics.connection_opened();
        let watcher = graceful.watcher();
        let (router, metrics, proxies) = (router.clone(), metrics.clone(), proxies.clone());
        tokio::spawn(async move {
            let closed = connection(stream, peer, router, limits, proxies, watcher).await;
            if let Some(why) = closed {
                metrics.connection_closed(why.name());
            }
            metrics.connection_ended();
            drop(slot);
        });
    }
    drop(listener);
    graceful.shutdown().await;
    Ok(())
}

/// The connection cap: a permit per connection, and a share per address.
struct Gate {
    slots: Arc<Semaphore>,
    per_address: Shares,
}

/// A connection's place under the cap, given back when it closes.
struct Slot {
    _share: Option<Share>,
    _permit: OwnedSemaphorePermit,
}

impl Gate {
    /// A place for a connection from `address`; a trusted proxy (which carries every
    /// client's connections) is held to the total cap only.
    fn admit(&self, address: IpAddr, proxy: bool) -> Result<Slot, &'static str> {
        let share = match proxy {
            true => None,
            false => Some(
                self.per_address
                    .take(&Holder::address(address))
                    .ok_or("this address has as many connections open as the server allows one")?,
            ),
        };
        let permit = self
            .slots
            .clone()
            .try_acquire_owned()
            .map_err(|_| "the server has as many connections open as it allows")?;
        Ok(Slot {
            _share: share,
            _permit: permit,
        })
    }
}

/// Answer a connection past the cap with a 503 and close it, in the background and briefly;
/// with too many refusals under way, close it at once.
fn refuse(stream: TcpStream, refusing: &Arc<Semaphore>, why: &str) {
    let Ok(permit) = refusing.clone().try_acquire_owned() else {
        return; // dropped: closed unanswered
    };
    let body = serde_json::json!({"error": {"code": "busy", "message": format!(
        "{why}; retry in {RETRY_AFTER_S} s"
    )}})
    .to_string();
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\n\
         retry-after: {RETRY_AFTER_S}\r\nconnection: close\r\ncontent-length: {}\r\n\r\n{body}",
        body.len()
    );
    tokio::spawn(async move {
        use tokio::io::AsyncWriteExt;
        let mut stream = stream;
        let _ = tokio::time::timeout(Duration::from_secs(1), async {
            stream.write_all(answer.as_bytes()).await?;
            stream.shutdown().await
        })
        .await;
        drop(permit);
    });
}

/// Serve one connection until it ends, or until one of its timeouts closes it (returned).
async fn connection(
    stream: TcpStream,
    peer: SocketAddr,
    router: Router,
    limits: Limits,
    proxies: Arc<TrustedProxies>,
    watcher: hyper_util::server::graceful::Watcher,
) -> Option<Closed> {
    let activity = Arc::new(Activity::new());
    let io = TokioIo::new(Watched {
        inner: stream,
        activity: activity.clone(),
    });
    let service = TowerToHyperService::new(Counted {
        inner: router,
        peer,
        proxies,
        activity: activity.clone(),
    });
    let conn = http1::Builder::new()
        .timer(TokioTimer::new())
        // The watchdog below times headers, so that idle time between requests is told
        // apart from a request's headers coming slowly.
        .header_read_timeout(None)
        .serve_connection(io, service);
    let conn = watcher.watch(conn);
    tokio::select! {
        r = conn => {
            if let Err(e) = r {
                tracing::debug!(%peer, error = %e, "connection ended with an error");
            }
            None
        }
        why = activity.watchdog(&limits) => {
            tracing::debug!(%peer, reason = why.name(), "closed a connection");
            Some(why)
        }
    }
}

/// Marks "none" in the times of [`Activity`].
const NONE: u64 = u64::MAX;

/// What a connection is doing, as its socket and its requests report it: the watchdog's
/// input. Times are milliseconds since the connection opened.
struct Activity {
    opened: Instant,
    /// Requests in progress (from the call to the end of the answer's body).
    active: AtomicUsize,
    /// When the next request began to arrive (the connection's start for the first),
    /// `NONE` while one is in progress or none has begun.
    head_started: AtomicU64,
    /// When the last request ended.
    idle_since: AtomicU64,
    /// When a write began to wait for the client to read, `NONE` when none is waiting.
    blocked_since: AtomicU64,
}

impl Activity {
    fn new() -> Activity {
        Activity {
            opened: Instant::now(),
            active: AtomicUsize::new(0),
            head_started: AtomicU64::new(0),
            idle_since: AtomicU64::new(0),
            blocked_since: AtomicU64::new(NONE),
        }
    }

    fn now(&self) -> u64 {
        self.opened.elapsed().as_millis() as u64
    }

    /// Bytes arrived: with no request in progress, a request has begun.
    fn read(&self) {
        if self.active.load(Ordering::Acquire) == 0 {
            let _ = self.head_started.compare_exchange(
                NONE,
                self.now(),
                Ordering::AcqRel,
                Ordering::Relaxed,
            );
        }
    }

    fn write_waits(&self) {
        let _ = self.blocked_since.compare_exchange(
            NONE,
            self.now(),
            Ordering::AcqRel,
            Ordering::Relaxed,
        );
    }

    fn write_done(&self) {
        self.blocked_since.store(NONE, Ordering::Release);
    }

    /// A request's headers are in: it is in progress until its answer ends.
    fn begin(self: &Arc<Self>) -> InProgress {
        self.active.fetch_add(1, Ordering::AcqRel);
        self.head_started.store(NONE, Ordering::Release);
        InProgress(self.clone())
    }

    /// What closes the connection now, if anything.
    fn verdict(&self, limits: &Limits) -> Option<Closed> {
        let now = self.now();
        let over = |since: u64, limit: Duration| {
            since != NONE && now.saturating_sub(since) > limit.as_millis() as u64
        };
        if self.active.load(Ordering::Acquire) > 0 {
            return over(
                self.blocked_since.load(Ordering::Acquire),
                limits.send_timeout,
            )
            .then_some(Closed::Send);
        }
        let head = self.head_started.load(Ordering::Acquire);
        if head != NONE {
            return over(head, limits.header_timeout).then_some(Closed::Header);
        }
        over(self.idle_since.load(Ordering::Acquire), limits.idle_timeout).then_some(Closed::Idle)
    }

    /// Resolves when a timeout closes the connection, checking a few times per shortest
    /// timeout (at most once a second).
    async fn watchdog(&self, limits: &Limits) -> Closed {
        let shortest = limits
            .header_timeout
            .min(limits.idle_timeout)
            .min(limits.send_timeout);
        let tick = (shortest / 4).clamp(Duration::from_millis(20), Duration::from_secs(1));
        loop {
            tokio::time::sleep(tick).await;
            if let Some(why) = self.verdict(limits) {
                return why;
            }
        }
    }
}

/// A request in progress; when dropped (its answer written, or abandoned), the connection
/// may idle again.
struct InProgress(Arc<Activity>);

impl Drop for InProgress {
    fn drop(&mut self) {
        let a = &self.0;
        a.idle_since.store(a.now(), Ordering::Release);
        a.active.fetch_sub(1, Ordering::AcqRel);
    }
}

/// The socket, reporting reads and waiting writes to the connection's [`Activity`].
struct Watched {
    inner: TcpStream,
    activity: Arc<Activity>,
}

impl AsyncRead for Watched {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let r = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(r, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.activity.read();
        }
        r
    }
}

impl AsyncWrite for Watched {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write(cx, buf);
        self.wrote(&r);
        r
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        self.wrote(&r);
        r
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

impl Watched {
    fn wrote(&self, r: &Poll<io::Result<usize>>) {
        match r {
            Poll::Pending => self.activity.write_waits(),
            Poll::Ready(_) => self.activity.write_done(),
        }
    }
}

/// The router, for one connection: each request carries the client's address (the peer's,
/// or behind a trusted proxy the one it forwards) and counts as in progress until its
/// answer's body ends.
#[derive(Clone)]
struct Counted {
    inner: Router,
    peer: SocketAddr,
    proxies: Arc<TrustedProxies>,
    activity: Arc<Activity>,
}

impl Service<Request<Incoming>> for Counted {
    type Response = Response<Body>;
    type Error = Infallible;
    type Future = Pin<Box<dyn Future<Output = Result<Response<Body>, Infallible>> + Send>>;

    fn poll_ready(&mut self, _cx: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        Poll::Ready(Ok(()))
    }

    fn call(&mut self, req: Request<Incoming>) -> Self::Future {
        let progress = self.activity.begin();
        let mut req = req.map(Body::new);
        let client = self.proxies.client(self.peer.ip(), req.headers());
        req.extensions_mut()
            .insert(ConnectInfo(SocketAddr::new(client, self.peer.port())));
        let call = self.inner.call(req);
        Box::pin(async move {
            let response = call.await?;
            Ok(response.map(|body| {
                Body::new(Tracked {
                    inner: body,
                    _progress: progress,
                })
            }))
        })
    }
}

/// An answer's body that keeps its request in progress until it is written or dropped.
struct Tracked {
    inner: Body,
    _progress: InProgress,
}

impl HttpBody for Tracked {
    type Data = axum::body::Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        Pin::new(&mut self.inner).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.inner.size_hint()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> Limits {
        Limits {
            header_timeout: Duration::from_millis(100),
            idle_timeout: Duration::from_millis(300),
            send_timeout: Duration::from_millis(200),
            ..Limits::default()
        }
    }

    /// Reads as if `ms` milliseconds had passed since `since` by moving the origin back.
    fn aged(a: &mut Activity, ms: u64) {
        a.opened -= Duration::from_millis(ms);
    }

    #[test]
    fn a_new_connection_has_the_header_time_to_send_its_first_request() {
        let l = limits();
        let mut a = Activity::new();
        assert_eq!(a.verdict(&l), None);
        aged(&mut a, 150);
        assert_eq!(a.verdict(&l), Some(Closed::Header));
    }

    #[test]
    fn between_requests_a_connection_idles_until_bytes_arrive() {
        let l = limits();
        let a = Arc::new(Activity::new());
        drop(a.begin()); // a request, answered
        let mut a = Arc::try_unwrap(a).ok().unwrap();
        // Idle: the header time does not apply, the idle time does.
        aged(&mut a, 150);
        assert_eq!(a.verdict(&l), None);
        aged(&mut a, 200);
        assert_eq!(a.verdict(&l), Some(Closed::Idle));
        // A request that begins to arrive has the header time from its first byte.
        a.idle_since.store(a.now(), Ordering::Release);
        a.read();
        aged(&mut a, 50);
        assert_eq!(a.verdict(&l), None);
        aged(&mut a, 100);
        assert_eq!(a.verdict(&l), Some(Closed::Header));
    }

    #[test]
    fn an_answer_nobody_reads_is_cut_after_the_send_time() {
        let l = limits();
        let mut a = Activity::new();
        a.active.store(1, Ordering::Release); // a request in progress
        a.write_waits();
        aged(&mut a, 150);
        assert_eq!(a.verdict(&l), None);
        aged(&mut a, 100);
        assert_eq!(a.verdict(&l), Some(Closed::Send));
        a.write_done();
        assert_eq!(a.verdict(&l), None);
    }

    #[test]
    fn the_gate_caps_connections_in_all_and_per_address() {
        let gate = Gate {
            slots: Arc::new(Semaphore::new(3)),
            per_address: Shares::new(2),
        };
        let a = IpAddr::from([10, 0, 0, 1]);
        let b = IpAddr::from([10, 0, 0, 2]);
        let s1 = gate.admit(a, false).unwrap();
        let _s2 = gate.admit(a, false).unwrap();
        assert!(gate.admit(a, false).is_err(), "per address");
        let _s3 = gate.admit(b, false).unwrap();
        assert!(gate.admit(b, false).is_err(), "in all");
        drop(s1);
        assert!(gate.admit(b, false).is_ok());
        // An IPv6 client is one whatever address of its /64 it comes from.
        let v6 = |last: u16| IpAddr::from([0x2001, 0xdb8, 0, 1, 0, 0, 0, last]);
        let gate = Gate {
            slots: Arc::new(Semaphore::new(10)),
            per_address: Shares::new(2),
        };
        let _x = gate.admit(v6(1), false).unwrap();
        let _y = gate.admit(v6(2), false).unwrap();
        assert!(gate.admit(v6(3), false).is_err());
    }
}
