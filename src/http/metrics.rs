//! Prometheus text metrics: request counts and latency, ingested and decoded frames.

use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Instant;

use axum::extract::{Request, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};

/// Latency histogram bucket bounds in seconds.
const BUCKETS: [f64; 10] = [0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.5, 1.0, 5.0];

#[derive(Default)]
pub struct Metrics {
    /// Requests that reached the router (answered or not).
    started: AtomicU64,
    /// Requests being handled now: a request whose client went away stops counting when the
    /// server drops it.
    in_flight: AtomicU64,
    requests: AtomicU64,
    errors: AtomicU64,
    latency_us_sum: AtomicU64,
    latency_buckets: [AtomicU64; BUCKETS.len()],
    ingested_frames: AtomicU64,
    decoded_frames: AtomicU64,
    uploaded_bytes: AtomicU64,
    stored_bytes: AtomicU64,
    served_bytes: AtomicU64,
    connections_open: AtomicU64,
    connections_refused: AtomicU64,
    closed_header: AtomicU64,
    closed_idle: AtomicU64,
    closed_send: AtomicU64,
    /// Live-stream requests sent on to the server coding the stream.
    forwarded: AtomicU64,
}

impl Metrics {
    /// A take stored: its frames, the upload's size and what it takes in the store.
    pub fn ingested(&self, frames: usize, uploaded: usize, stored: usize) {
        self.ingested_frames
            .fetch_add(frames as u64, Ordering::Relaxed);
        self.uploaded_bytes
            .fetch_add(uploaded as u64, Ordering::Relaxed);
        self.stored_bytes
            .fetch_add(stored as u64, Ordering::Relaxed);
    }

    /// A range served: its frames and the decoded bytes behind the response.
    pub fn decoded(&self, frames: usize, bytes: usize) {
        self.decoded_frames
            .fetch_add(frames as u64, Ordering::Relaxed);
        self.served_bytes.fetch_add(bytes as u64, Ordering::Relaxed);
    }

    /// A live stream's request answered by the server that codes it, through this one.
    pub fn forwarded(&self) {
        self.forwarded.fetch_add(1, Ordering::Relaxed);
    }

    pub fn connection_opened(&self) {
        self.connections_open.fetch_add(1, Ordering::Relaxed);
    }

    pub fn connection_ended(&self) {
        self.connections_open.fetch_sub(1, Ordering::Relaxed);
    }

    /// A connection past the cap, answered 503 (or closed unanswered).
    pub fn connection_refused(&self) {
        self.connections_refused.fetch_add(1, Ordering::Relaxed);
    }

    /// A connection the server closed when one of its timeouts ran out: `header_timeout`,
    /// `idle_timeout` or `send_timeout`.
    pub fn connection_closed(&self, reason: &str) {
        let c = match reason {
            "header_timeout" => &self.closed_header,
            "idle_timeout" => &self.closed_idle,
            _ => &self.closed_send,
        };
        c.fetch_add(1, Ordering::Relaxed);
    }

    fn observe(&self, seconds: f64, error: bool) {
        self.requests.fetch_add(1, Ordering::Relaxed);
        if error {
            self.errors.fetch_add(1, Ordering::Relaxed);
        }
        self.latency_us_sum
            .fetch_add((seconds * 1e6) as u64, Ordering::Relaxed);
        // One count, in the first bucket that holds it (the rendering sums them up): every
        // request pays one increment, not one per bucket it is under (ten, for a fast one),
        // on counters every thread shares.
        if let Some(c) = BUCKETS
            .iter()
            .zip(&self.latency_buckets)
            .find_map(|(b, c)| (seconds <= *b).then_some(c))
        {
            c.fetch_add(1, Ordering::Relaxed);
        }
    }

    pub fn render_text(&self) -> String {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let mut s = String::new();
        s += "# TYPE mocapstore_http_requests_started_total counter\n";
        s += &format!(
            "mocapstore_http_requests_started_total {}\n",
            g(&self.started)
        );
        s += "# TYPE mocapstore_http_requests_in_flight gauge\n";
        s += &format!(
            "mocapstore_http_requests_in_flight {}\n",
            g(&self.in_flight)
        );
        s += "# TYPE mocapstore_http_requests_total counter\n";
        s += &format!("mocapstore_http_requests_total {}\n", g(&self.requests));
        s += "# TYPE mocapstore_http_errors_total counter\n";
        s += &format!("mocapstore_http_errors_total {}\n", g(&self.errors));
        s += "# TYPE mocapstore_http_request_seconds histogram\n";
        let mut below = 0;
        for (b, c) in BUCKETS.iter().zip(&self.latency_buckets) {
            below += g(c);
            s += &format!("mocapstore_http_request_seconds_bucket{{le=\"{b}\"}} {below}\n");
        }
        s += &format!(
            "mocapstore_http_request_seconds_bucket{{le=\"+Inf\"}} {}\n",
            g(&self.requests)
        );
        s += &format!(
            "mocapstore_http_request_seconds_sum {}\n",
            g(&self.latency_us_sum) as f64 / 1e6
        );
        s += &format!(
            "mocapstore_http_request_seconds_count {}\n",
            g(&self.requests)
        );
        s += "# TYPE mocapstore_ingested_frames_total counter\n";
        s += &format!(
            "mocapstore_ingested_frames_total {}\n",
            g(&self.ingested_frames)
        );
        s += "# TYPE mocapstore_decoded_frames_total counter\n";
        s += &format!(
            "mocapstore_decoded_frames_total {}\n",
            g(&self.decoded_frames)
        );
        for (name, v) in [
            ("uploaded", &self.uploaded_bytes),
            ("stored", &self.stored_bytes),
            ("served", &self.served_bytes),
        ] {
            s += &format!("# TYPE mocapstore_{name}_bytes_total counter\n");
            s += &format!("mocapstore_{name}_bytes_total {}\n", g(v));
        }
        s += "# TYPE mocapstore_connections_open gauge\n";
        s += &format!(
            "mocapstore_connections_open {}\n",
            g(&self.connections_open)
        );
        s += "# TYPE mocapstore_connections_refused_total counter\n";
        s += &format!(
            "mocapstore_connections_refused_total {}\n",
            g(&self.connections_refused)
        );
        s += "# TYPE mocapstore_connections_closed_total counter\n";
        for (why, v) in [
            ("header_timeout", &self.closed_header),
            ("idle_timeout", &self.closed_idle),
            ("send_timeout", &self.closed_send),
        ] {
            s += &format!(
                "mocapstore_connections_closed_total{{reason=\"{why}\"}} {}\n",
                g(v)
            );
        }
        s += "# HELP mocapstore_stream_requests_forwarded_total live-stream requests answered by \
              the server coding the stream, through this one\n";
        s += "# TYPE mocapstore_stream_requests_forwarded_total counter\n";
        s += &format!(
            "mocapstore_stream_requests_forwarded_total {}\n",
            g(&self.forwarded)
        );
        if let Some(cpu) = process_cpu_seconds() {
            // The Prometheus client libraries' standard name: what a benchmark (the Python
            // client's) reads to set the server's CPU per request beside its own.
            s += "# HELP process_cpu_seconds_total user and system CPU time of the server\n";
            s += "# TYPE process_cpu_seconds_total counter\n";
            s += &format!("process_cpu_seconds_total {cpu}\n");
        }
        s
    }
}

/// The process's user and system CPU time, seconds, from `/proc/self/stat` (all threads);
/// `None` where there is no `/proc` (the metric is then left out).
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command (which may hold spaces) closed by the last ')'; utime and
    // stime are the 14th and 15th fields, the 12th and 13th after it, in clock ticks of
    // USER_HZ, which is 100 on every Linux architecture's user ABI.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_ascii_whitespace().skip(11);
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some((utime + stime) as f64 / 100.0)
}

/// Counts a request in flight until it is answered or dropped.
struct InFlight(Arc<Metrics>);

impl Drop for InFlight {
    fn drop(&mut self) {
        self.0.in_flight.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Counts every request that reaches the router, and its latency when it is answered: the
/// outermost layer but tracing's. Written as a service, not with `middleware::from_fn`,
/// which boxes the layers within and the future anew for every request.
#[derive(Clone)]
pub struct CountRequests(pub Arc<Metrics>);

impl<S> tower::Layer<S> for CountRequests {
    type Service = RequestCounter<S>;

    fn layer(&self, inner: S) -> RequestCounter<S> {
        RequestCounter {
            inner,
            metrics: self.0.clone(),
        }
    }
}

/// A service whose requests are counted ([`CountRequests`]).
#[derive(Clone)]
pub struct RequestCounter<S> {
    inner: S,
    metrics: Arc<Metrics>,
}

impl<S> tower::Service<Request> for RequestCounter<S>
where
    S: tower::Service<Request, Response = Response>,
{
    type Response = Response;
    type Error = S::Error;
    type Future = Counting<S::Future>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), S::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: Request) -> Self::Future {
        let m = &self.metrics;
        m.started.fetch_add(1, Ordering::Relaxed);
        m.in_flight.fetch_add(1, Ordering::Relaxed);
        Counting {
            t0: Instant::now(),
            guard: Some(InFlight(m.clone())),
            inner: self.inner.call(req),
        }
    }
}

pin_project_lite::pin_project! {
    /// A counted request until it is answered; dropped unanswered, it stops counting as in
    /// flight and is not observed.
    pub struct Counting<F> {
        #[pin]
        inner: F,
        t0: Instant,
        // Taken when the answer is ready: in flight until then, not until the future is dropped.
        guard: Option<InFlight>,
    }
}

impl<F, E> Future for Counting<F>
where
    F: Future<Output = Result<Response, E>>,
{
    type Output = Result<Response, E>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let this = self.project();
        let answered = std::task::ready!(this.inner.poll(cx));
        // Observed, then no longer in flight (the guard dropped), as the answer is ready.
        let guard = this.guard.take();
        if let (Some(InFlight(m)), Ok(r)) = (&guard, &answered) {
            m.observe(this.t0.elapsed().as_secs_f64(), !r.status().is_success());
        }
        Poll::Ready(answered)
    }
}

pub async fn render(State(state): State<super::AppState>) -> Response {
    let mut text = state.metrics.render_text();
    // What the server holds now, against its limits (gauges).
    let (answers_held, answers_peak, answer_peak) = state.answers.held();
    for (name, help, value) in [
        (
            "mocapstore_request_body_bytes_held",
            "request bodies held now (reserved as they arrive), against the in-flight budget",
            state.bodies.reserved_bytes(),
        ),
        (
            "mocapstore_request_body_bytes_budget",
            "the in-flight budget for request bodies",
            state.bodies.total_bytes(),
        ),
        (
            "mocapstore_request_body_bytes_share",
            "what one caller's request bodies may hold at once",
            state.bodies.share_bytes(),
        ),
        (
            "mocapstore_answer_bytes_reserved",
            "what range answers being written have reserved now",
            state.answers.reserved_bytes(),
        ),
        (
            "mocapstore_answer_bytes_held",
            "what range answers being written hold now (their buffers)",
            answers_held,
        ),
        (
            "mocapstore_answer_bytes_held_peak",
            "the most range answers held at once since the server started",
            answers_peak,
        ),
        (
            "mocapstore_answer_bytes_one_peak",
            "the most one range answer held since the server started",
            answer_peak,
        ),
        (
            "mocapstore_answer_bytes_budget",
            "the budget for range answers",
            state.answers.total_bytes(),
        ),
        (
            "mocapstore_streams_open",
            "live streams open on this server",
            state.streams.open_count() as u64,
        ),
    ] {
        text += &format!("# HELP {name} {help}\n# TYPE {name} gauge\n{name} {value}\n");
    }
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], text).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `/metrics` gives each bucket every request at or under its bound, though a request
    /// is counted once.
    #[test]
    fn latency_buckets_count_every_request_at_or_under_their_bound() {
        let m = Metrics::default();
        for seconds in [0.0005, 0.001, 0.003, 2.0, 9.0] {
            m.observe(seconds, false);
        }
        let text = m.render_text();
        let bucket = |le: &str| -> u64 {
            let prefix = format!("mocapstore_http_request_seconds_bucket{{le=\"{le}\"}} ");
            let line = text.lines().find(|l| l.starts_with(&prefix)).unwrap();
            line[prefix.len()..].parse().unwrap()
        };
        assert_eq!(bucket("0.001"), 2);
        assert_eq!(bucket("0.002"), 2);
        assert_eq!(bucket("0.005"), 3);
        assert_eq!(bucket("1"), 3);
        assert_eq!(bucket("5"), 4);
        assert_eq!(bucket("+Inf"), 5);
    }

    /// Another thread's work shows in the count (the main thread waits meanwhile), and
    /// the count does not run ahead of the CPU the process can have had.
    #[cfg(target_os = "linux")]
    #[test]
    fn process_cpu_time_counts_the_work_of_every_thread() {
        let before = process_cpu_seconds().expect("/proc/self/stat reads");
        let wall = Instant::now();
        let reached = std::thread::spawn(move || {
            let mut x = 0u64;
            while wall.elapsed().as_secs() < 30 {
                for _ in 0..100_000 {
                    x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                }
                if process_cpu_seconds().unwrap() >= before + 0.2 {
                    return true;
                }
            }
            false
        })
        .join()
        .unwrap();
        assert!(reached, "0.2 s of another thread's work is counted");
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
        let spent = process_cpu_seconds().unwrap() - before;
        assert!(
            spent <= wall.elapsed().as_secs_f64() * cores + 0.05,
            "{spent}"
        );
    }
}
