//! `mocapstore streamtest`: live-stream ingest over HTTP — frames per second sustained, and
//! the delay from a frame's arrival to its being fetchable.
//!
//! It starts the real service on 127.0.0.1:0 over a temporary SQLite file, trains an lsdt
//! basis on a generated take of the same layout, then
//! 1. appends a long generated take as fast as the service takes it (batches of `--batch`
//!    frames) and reports frames per second;
//! 2. replays a take in real time (`--live-batch` frames per request, as a capture system
//!    would send them) with and without `flush`, and reports, per frame, the time from when
//!    it was captured until a range fetch that includes it succeeds.
//!
//! With `--server URL` (repeatable) it measures running servers instead — several behind
//! one database: each stream is opened through the first, and its appends, range fetches
//! and finish are spread over all of them round-robin (request `i` to server `i mod N`), as
//! a balancer would; the servers that do not code a stream forward its requests to the one
//! that does. No basis is trained there (streams code with the layout's newest, or the
//! codec's untrained one); the streams are deleted after when the token may.

use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use clap::Args;
use serde_json::{json, Value};

use mocapstore::http::{Application, Config};
use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use mocapstore::store::Store;

#[derive(Args)]
pub struct StreamArgs {
    /// Seconds of frames appended as fast as possible.
    #[arg(long, default_value_t = 120)]
    seconds: usize,
    #[arg(long, default_value_t = 120.0)]
    fps: f64,
    #[arg(long, default_value_t = 38)]
    points: usize,
    /// Frames per append in the throughput run.
    #[arg(long, default_value_t = 120)]
    batch: usize,
    /// Frames per append in the real-time runs.
    #[arg(long, default_value_t = 12)]
    live_batch: usize,
    /// Seconds replayed in real time (per run).
    #[arg(long, default_value_t = 10)]
    live_seconds: usize,
    /// Running servers to measure (repeatable, or comma-separated) instead of one started
    /// here; requests are spread over them round-robin.
    #[arg(long = "server", value_delimiter = ',')]
    servers: Vec<String>,
    /// API token for `--server`s that need one (write scope; admin to delete the streams).
    #[arg(long, env = "MOCAP_TOKEN")]
    token: Option<String>,
}

/// The servers requests go to, in turn.
struct Servers {
    urls: Vec<String>,
    /// Requests sent through [`Servers::pick`].
    sent: AtomicUsize,
}

impl Servers {
    fn new(urls: Vec<String>) -> Servers {
        Servers {
            urls,
            sent: AtomicUsize::new(0),
        }
    }

    /// The next server, round-robin.
    fn pick(&self) -> &str {
        let i = self.sent.fetch_add(1, Ordering::Relaxed);
        &self.urls[i % self.urls.len()]
    }

    fn first(&self) -> &str {
        &self.urls[0]
    }
}

pub fn run(args: &StreamArgs) -> ExitCode {
    let rt = match tokio::runtime::Runtime::new() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("mocapstore streamtest: {e}");
            return ExitCode::FAILURE;
        }
    };
    match rt.block_on(test(args)) {
        Ok(report) => {
            println!("{report}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore streamtest: {e}");
            ExitCode::FAILURE
        }
    }
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

async fn post_json(client: &reqwest::Client, url: String, body: &Value) -> Result<Value, String> {
    let r = client
        .post(url)
        .json(body)
        .send()
        .await
        .map_err(|e| e.to_string())?;
    let status = r.status();
    let v: Value = r.json().await.map_err(|e| e.to_string())?;
    if !status.is_success() {
        return Err(format!("{status}: {v}"));
    }
    Ok(v)
}

async fn open(
    client: &reqwest::Client,
    base: &str,
    fps: f64,
    points: usize,
) -> Result<String, String> {
    let v = post_json(
        client,
        format!("{base}/v1/streams"),
        &json!({"fps": fps, "points": points, "max_error_mm": 1.0}),
    )
    .await?;
    v["id"]
        .as_str()
        .map(str::to_string)
        .ok_or("no stream id".into())
}

async fn append(
    client: &reqwest::Client,
    base: &str,
    id: &str,
    frames: &[f32],
    flush: bool,
) -> Result<Value, String> {
    let r = client
        .post(format!("{base}/v1/streams/{id}/frames?flush={flush}"))
        .header("content-type", "application/octet-stream")
        .body(f32_bytes(frames))
        .send()
        .await
        .map_err(|e| e.to_string())?;
    let status = r.status();
    let v: Value = r.json().await.map_err(|e| e.to_string())?;
    if !status.is_success() {
        return Err(format!("{status}: {v}"));
    }
    Ok(v)
}

async fn test(args: &StreamArgs) -> Result<String, String> {
    if !args.servers.is_empty() {
        let urls = args
            .servers
            .iter()
            .map(|s| s.trim_end_matches('/').to_string())
            .collect();
        let client = super::token::client(args.token.as_deref())?;
        return measure(args, &client, &Servers::new(urls)).await;
    }
    let dir = std::env::temp_dir().join(format!("mocapstore-stream-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let url = format!("sqlite://{}", dir.join("store.db").display());
    let store = Store::open(&url).await.map_err(|e| e.to_string())?;
    let app = Application::with_store(
        store,
        Config {
            listen: "127.0.0.1:0".into(),
            database_url: url,
            decoded_cache_mib: 64,
            ..Config::default()
        },
    )
    .await?;
    let base = format!("http://{}", app.local_addr());
    let (stop, rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until(async {
        let _ = rx.await;
    }));
    let client = reqwest::Client::new();
    let (fps, points) = (args.fps, args.points);

    // A basis for the layout, trained on a minute of another take of it.
    let training = walker((60.0 * fps) as usize, points, fps, 1, 0.0);
    let r = client
        .post(format!("{base}/v1/takes?library=training&codec=quant"))
        .body(formats::write(&training, Format::Json).map_err(|e| e.to_string())?)
        .send()
        .await
        .map_err(|e| e.to_string())?;
    if !r.status().is_success() {
        return Err(format!("ingest of the training take: {}", r.status()));
    }
    let job = post_json(
        &client,
        format!("{base}/v1/bases"),
        &json!({"library": "training"}),
    )
    .await?;
    let job_id = job["id"].as_str().unwrap_or_default().to_string();
    loop {
        let j: Value = client
            .get(format!("{base}/v1/jobs/{job_id}"))
            .send()
            .await
            .map_err(|e| e.to_string())?
            .json()
            .await
            .map_err(|e| e.to_string())?;
        match j["state"].as_str() {
            Some("succeeded") => break,
            Some("failed") => return Err(format!("training failed: {j}")),
            _ => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
    let report = measure(args, &client, &Servers::new(vec![base])).await;
    let _ = stop.send(());
    let _ = server.await;
    let _ = std::fs::remove_dir_all(&dir);
    report
}

/// The two runs against `servers`: throughput, then delay in real time.
async fn measure(
    args: &StreamArgs,
    client: &reqwest::Client,
    servers: &Servers,
) -> Result<String, String> {
    let (fps, points) = (args.fps, args.points);
    let w = points * 3;
    let mut opened = Vec::new();

    // 1. Throughput.
    let take = walker(args.seconds * fps as usize, points, fps, 2, 0.0);
    let id = open(client, servers.first(), fps, points).await?;
    opened.push(id.clone());
    let t0 = Instant::now();
    for batch in take.positions().chunks(args.batch.max(1) * w) {
        append(client, servers.pick(), &id, batch, false).await?;
    }
    let info = post_json(
        client,
        format!("{}/v1/streams/{id}/finish", servers.pick()),
        &json!({}),
    )
    .await?;
    let secs = t0.elapsed().as_secs_f64();
    let frames = take.frame_count();
    let mut report = format!(
        "streaming {} frames of {points} points at {fps} fps, batches of {}: {:.0} frames/s sustained ({:.1}× real time), ratio {:.1}, max {:.3} mm\n",
        frames,
        args.batch,
        frames as f64 / secs,
        frames as f64 / secs / fps,
        info["ratio"].as_f64().unwrap_or(0.0),
        info["max_mm"].as_f64().unwrap_or(0.0),
    );

    // 2. Delay from capture to fetchable, in real time.
    let live = walker(args.live_seconds * fps as usize, points, fps, 3, 0.0);
    for flush in [true, false] {
        let id = open(client, servers.first(), fps, points).await?;
        opened.push(id.clone());
        let start = Instant::now();
        let mut delays = Vec::new();
        let mut committed = 0usize;
        let mut captured_at: Vec<f64> = Vec::new();
        let batch = args.live_batch.max(1);
        for (i, chunk) in live.positions().chunks(batch * w).enumerate() {
            // The batch's last frame is captured at this moment of the take.
            let n = chunk.len() / w;
            let due = ((i * batch + n) as f64 / fps) as f32;
            let now = start.elapsed().as_secs_f32();
            if due > now {
                tokio::time::sleep(Duration::from_secs_f32(due - now)).await;
            }
            for f in 0..n {
                captured_at.push((i * batch + f + 1) as f64 / fps);
            }
            let info = append(client, servers.pick(), &id, chunk, flush).await?;
            let now_committed = info["frames_committed"].as_u64().unwrap_or(0) as usize;
            if now_committed > committed {
                // Fetchable from now: prove it with a range fetch of the newest frames.
                let r = client
                    .get(format!(
                        "{}/v1/takes/{id}/frames?start={}&end={now_committed}&format=f32",
                        servers.pick(),
                        now_committed - 1
                    ))
                    .send()
                    .await
                    .map_err(|e| e.to_string())?;
                if !r.status().is_success() {
                    return Err(format!("fetch of committed frames: {}", r.status()));
                }
                let t = start.elapsed().as_secs_f64();
                for &c in &captured_at[committed..now_committed] {
                    delays.push((t - c) * 1e3);
                }
                committed = now_committed;
            }
        }
        post_json(
            client,
            format!("{}/v1/streams/{id}/finish", servers.pick()),
            &json!({}),
        )
        .await?;
        delays.sort_by(f64::total_cmp);
        report += &format!(
            "real time, {batch} frames per append, flush={flush}: capture→fetchable p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms ({} frames)\n",
            percentile(&delays, 0.5),
            percentile(&delays, 0.99),
            delays.last().copied().unwrap_or(0.0),
            delays.len()
        );
    }
    if servers.urls.len() > 1 {
        report += &format!(
            "{} requests spread round-robin over {} servers ({}); each stream coded by the \
             server it was opened on, the others forwarding to it\n",
            servers.sent.load(Ordering::Relaxed),
            servers.urls.len(),
            servers.urls.join(", ")
        );
    }
    if !args.servers.is_empty() {
        // Leave no take behind (an admin token may delete them; others leave them, and say so).
        let mut left = Vec::new();
        for id in opened {
            let r = client
                .delete(format!("{}/v1/takes/{id}", servers.first()))
                .send()
                .await;
            if !r.is_ok_and(|r| r.status().is_success()) {
                left.push(id);
            }
        }
        if !left.is_empty() {
            report += &format!(
                "(streams {} were left: the token may not delete them)\n",
                left.join(", ")
            );
        }
    }
    Ok(report)
}
