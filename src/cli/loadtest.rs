//! `mocapstore loadtest`: latency and throughput of range fetches over HTTP, against reading
//! the same ranges as raw f32 from a SQLite BLOB through an equivalent route, in one run.
//!
//! It starts the real service on 127.0.0.1:0 over a temporary SQLite file, ingests a
//! generated take (default 10 minutes, 38 points, 120 fps), stores the same frames as raw f32
//! in one-second BLOBs, then runs a fixed number of requests from concurrent clients to
//! each route and prints p50/p99 latency and requests per second. The routes take turns,
//! a share of the requests each, four times over, so that what else the machine does falls
//! on all of them alike; the route with a read token is served by a second server over a
//! copy of the database (once a token exists, every request to a database needs one).
//!
//! With `--server URL` (repeatable) it measures running servers instead — several behind
//! no balancer, sharing one database: the take is ingested through the first, and the
//! clients are spread over them round-robin (client `c` asks server `c mod N`), so a take
//! stored through one is read through all. No baseline then (the raw BLOBs need the
//! database), and the take is deleted at the end when the token may.

use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::{Query, State};
use axum::routing::get;
use clap::Args;
use serde::Deserialize;
use sqlx::SqlitePool;

use mocapstore::http::{Application, Config};
use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::{walker, Rng};
use mocapstore::store::Store;

#[derive(Args)]
pub struct LoadArgs {
    /// Length of the generated take, seconds.
    #[arg(long, default_value_t = 600)]
    seconds: usize,
    #[arg(long, default_value_t = 120.0)]
    fps: f64,
    #[arg(long, default_value_t = 38)]
    points: usize,
    /// Concurrent clients.
    #[arg(long, default_value_t = 16)]
    clients: usize,
    /// Requests per route (spread over the clients).
    #[arg(long, default_value_t = 20_000)]
    requests: usize,
    /// The service's decoded-chunk cache, MiB (0: every request decodes).
    #[arg(long, default_value_t = 256)]
    decoded_cache_mib: usize,
    /// Running servers to measure (repeatable, or comma-separated) instead of one started
    /// here; the clients are spread over them round-robin.
    #[arg(long = "server", value_delimiter = ',')]
    servers: Vec<String>,
    /// API token for `--server`s that need one (write scope to ingest; admin to delete).
    #[arg(long, env = "MOCAP_TOKEN")]
    token: Option<String>,
}

#[derive(Deserialize)]
struct RawQuery {
    second: i64,
}

/// The baseline: one-second raw f32 BLOBs straight out of SQLite.
async fn raw_blob(State(pool): State<SqlitePool>, Query(q): Query<RawQuery>) -> Vec<u8> {
    sqlx::query_scalar::<_, Vec<u8>>("SELECT data FROM raw_seconds WHERE second = $1")
        .bind(q.second)
        .fetch_one(&pool)
        .await
        .unwrap_or_default()
}

pub fn run(args: &LoadArgs) -> ExitCode {
    let rt = match tokio::runtime::Runtime::new() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("mocapstore loadtest: {e}");
            return ExitCode::FAILURE;
        }
    };
    let run = async {
        if args.servers.is_empty() {
            load(args).await
        } else {
            load_servers(args).await
        }
    };
    match rt.block_on(run) {
        Ok(report) => {
            println!("{report}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore loadtest: {e}");
            ExitCode::FAILURE
        }
    }
}

async fn load(args: &LoadArgs) -> Result<String, String> {
    let dir = std::env::temp_dir().join(format!("mocapstore-load-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let url = format!("sqlite://{}", dir.join("load.db").display());
    let store = Store::open(&url).await.map_err(|e| e.to_string())?;
    let config = Config {
        listen: "127.0.0.1:0".into(),
        database_url: url.clone(),
        decoded_cache_mib: args.decoded_cache_mib,
        // The limiter runs for requests with a token (measured below) but never refuses.
        limits: mocapstore::limits::Limits {
            requests_per_s: 1_000_000_000,
            request_burst: 1_000_000_000,
            ..mocapstore::limits::Limits::default()
        },
        ..Config::default()
    };
    let app = Application::with_store(store.clone(), config.clone()).await?;
    let base = format!("http://{}", app.local_addr());
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until(async {
        let _ = stopped.await;
    }));

    // The take, ingested over HTTP (timed: ingest throughput).
    let frames = (args.seconds as f64 * args.fps) as usize;
    let motion = walker(frames, args.points, args.fps, 11, 0.0);
    let body = formats::write(&motion, Format::Npy).map_err(|e| e.to_string())?;
    let client = reqwest::Client::new();
    let t0 = Instant::now();
    let r = client
        .post(format!(
            "{base}/v1/takes?name=load&unit=mm&fps={}&max_error_mm=1",
            args.fps
        ))
        .body(body)
        .send()
        .await
        .map_err(|e| e.to_string())?;
    let ingest_s = t0.elapsed().as_secs_f64();
    let report: serde_json::Value = r.json().await.map_err(|e| e.to_string())?;
    let id = report["id"]
        .as_str()
        .ok_or(format!("ingest failed: {report}"))?
        .to_string();

    // The baseline table and its route, on a second listener.
    let Store::Sqlite(pool) = &store else {
        unreachable!("loadtest uses SQLite")
    };
    sqlx::query(
        "CREATE TABLE IF NOT EXISTS raw_seconds (second INTEGER PRIMARY KEY, data BLOB NOT NULL)",
    )
    .execute(pool)
    .await
    .map_err(|e| e.to_string())?;
    let per = args.fps.round() as usize * args.points * 3;
    for (s, chunk) in motion.positions().chunks(per).enumerate() {
        let bytes: Vec<u8> = chunk.iter().flat_map(|v| v.to_le_bytes()).collect();
        sqlx::query("INSERT INTO raw_seconds (second, data) VALUES ($1, $2)")
            .bind(s as i64)
            .bind(bytes)
            .execute(pool)
            .await
            .map_err(|e| e.to_string())?;
    }
    let raw_app = axum::Router::new()
        .route("/raw", get(raw_blob))
        .with_state(pool.clone());
    let raw_listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .map_err(|e| e.to_string())?;
    let raw_base = format!(
        "http://{}",
        raw_listener.local_addr().map_err(|e| e.to_string())?
    );
    let raw_server = tokio::spawn(async move { axum::serve(raw_listener, raw_app).await });

    let seconds = args.seconds.max(2);
    let fps = args.fps;
    let id_for_token = id.clone();
    let codec_url = move |_client: usize, s: usize| {
        format!("{base}/v1/takes/{id}/frames?t0={s}&t1={}&format=f32", s + 1)
    };
    let raw_url = move |_client: usize, s: usize| format!("{raw_base}/raw?second={s}");
    let mut out = format!(
        "take: {frames} frames × {} points at {fps} fps ({} s); stored as {} at ratio {:.1}, max error {:.3} mm\n\
         ingest over HTTP: {:.2} s = {:.0} frames/s (parse + every candidate codec + store)\n\n\
         | route (1-s range, {} clients, {} requests; decoded-chunk cache {} MiB) | p50 ms | p99 ms | req/s |\n|---|---:|---:|---:|\n",
        args.points,
        args.seconds,
        report["codec"].as_str().unwrap_or("?"),
        report["ratio"].as_f64().unwrap_or(0.0),
        report["max_mm"].as_f64().unwrap_or(0.0),
        ingest_s,
        frames as f64 / ingest_s,
        args.clients,
        args.requests,
        args.decoded_cache_mib
    );
    let codec_url: Arc<UrlOf> = Arc::new(codec_url);
    let route = "GET /v1/takes/{id}/frames?t0&t1&format=f32";

    // The cost of access control: the same route on a second server over a copy of the
    // database in which a read token exists, each request's bearer checked (a cached
    // lookup), its scope and the rate limiter. A copy, because once a token exists every
    // request to that database needs one: the first server stays anonymous.
    let token_db = dir.join("token.db");
    sqlx::query("VACUUM INTO $1")
        .bind(token_db.display().to_string())
        .execute(pool)
        .await
        .map_err(|e| e.to_string())?;
    let token_url = format!("sqlite://{}", token_db.display());
    let token_store = Store::open(&token_url).await.map_err(|e| e.to_string())?;
    let token = mocapstore::service::access::create_token(
        &token_store,
        mocapstore::service::access::TokenRequest {
            name: "loadtest".into(),
            scope: "read".into(),
            libraries: None,
            expires_at: None,
        },
    )
    .await
    .map_err(|e| e.to_string())?;
    let token_app = Application::with_store(
        token_store,
        Config {
            database_url: token_url,
            ..config.clone()
        },
    )
    .await?;
    let token_base = format!("http://{}", token_app.local_addr());
    let (token_stop, token_stopped) = tokio::sync::oneshot::channel::<()>();
    let token_server = tokio::spawn(token_app.run_until(async {
        let _ = token_stopped.await;
    }));
    let take = id_for_token;
    let token_url: Arc<UrlOf> = Arc::new(move |_client: usize, s: usize| {
        format!(
            "{token_base}/v1/takes/{take}/frames?t0={s}&t1={}&format=f32",
            s + 1
        )
    });
    let authed = super::token::client(Some(&token.secret))?;

    // The rows take turns, ROUNDS times over (A B C A B C …), each a share of the requests:
    // what the machine does meanwhile falls on all of them alike, not on whichever ran last.
    let rows: [(String, &reqwest::Client, Arc<UrlOf>); 3] = [
        (route.to_string(), &client, codec_url),
        (
            "raw f32 BLOB from SQLite (baseline)".to_string(),
            &client,
            Arc::new(raw_url) as Arc<UrlOf>,
        ),
        (
            format!("{route}, with a read token (auth + rate limiter)"),
            &authed,
            token_url,
        ),
    ];
    let mut runs: Vec<Run> = rows.iter().map(|_| Run::default()).collect();
    for _ in 0..ROUNDS {
        for ((_, client, url), run) in rows.iter().zip(runs.iter_mut()) {
            let r = hammer(
                client,
                url.clone(),
                seconds - 1,
                args.clients,
                args.requests.div_ceil(ROUNDS),
            )
            .await?;
            run.add(r);
        }
    }
    for ((name, _, _), run) in rows.iter().zip(runs.iter_mut()) {
        let (p50, p99, rps) = run.summary();
        out += &format!("| {name} | {p50:.3} | {p99:.3} | {rps:.0} |\n");
    }
    let _ = token_stop.send(());
    let _ = token_server.await;
    let _ = stop.send(());
    let _ = server.await;
    raw_server.abort();
    let _ = std::fs::remove_dir_all(&dir);
    Ok(out)
}

/// The URL client `c` asks for range `s`.
type UrlOf = dyn Fn(usize, usize) -> String + Send + Sync;

/// How many turns each row of the loadtest takes.
const ROUNDS: usize = 4;

/// One row's requests over its turns: every latency, and the time its turns took.
#[derive(Default)]
struct Run {
    latencies: Vec<Duration>,
    seconds: f64,
}

impl Run {
    fn add(&mut self, (latencies, seconds): (Vec<Duration>, f64)) {
        self.latencies.extend(latencies);
        self.seconds += seconds;
    }

    /// (p50 ms, p99 ms, req/s).
    fn summary(&mut self) -> (f64, f64, f64) {
        let all = &mut self.latencies;
        all.sort();
        let pct = |p: f64| all[((all.len() - 1) as f64 * p) as usize].as_secs_f64() * 1e3;
        (pct(0.5), pct(0.99), all.len() as f64 / self.seconds)
    }
}

/// `requests` GETs of random ranges from `clients` concurrent tasks: every latency, and the
/// seconds they took together.
async fn hammer(
    client: &reqwest::Client,
    url: Arc<UrlOf>,
    ranges: usize,
    clients: usize,
    requests: usize,
) -> Result<(Vec<Duration>, f64), String> {
    let per_client = requests.div_ceil(clients.max(1));
    let t0 = Instant::now();
    let mut tasks = Vec::new();
    for c in 0..clients.max(1) {
        let (client, url) = (client.clone(), url.clone());
        tasks.push(tokio::spawn(async move {
            let mut rng = Rng::new(c as u64 + 1);
            let mut lat = Vec::with_capacity(per_client);
            for _ in 0..per_client {
                let u = url(c, rng.below(ranges));
                let t = Instant::now();
                let r = client.get(&u).send().await.map_err(|e| e.to_string())?;
                if !r.status().is_success() {
                    return Err(format!("{u}: {}", r.status()));
                }
                r.bytes().await.map_err(|e| e.to_string())?;
                lat.push(t.elapsed());
            }
            Ok::<Vec<Duration>, String>(lat)
        }));
    }
    let mut all = Vec::new();
    for t in tasks {
        all.extend(t.await.map_err(|e| e.to_string())??);
    }
    Ok((all, t0.elapsed().as_secs_f64()))
}

/// The run against `--server`s: the take ingested through the first, the clients spread over
/// all of them round-robin.
async fn load_servers(args: &LoadArgs) -> Result<String, String> {
    let servers: Vec<String> = args
        .servers
        .iter()
        .map(|s| s.trim_end_matches('/').to_string())
        .collect();
    let client = super::token::client(args.token.as_deref())?;
    let frames = (args.seconds as f64 * args.fps) as usize;
    let motion = walker(frames, args.points, args.fps, 11, 0.0);
    let body = formats::write(&motion, Format::Npy).map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    let r = client
        .post(format!(
            "{}/v1/takes?name=loadtest&library=loadtest&unit=mm&fps={}&max_error_mm=1",
            servers[0], args.fps
        ))
        .body(body)
        .send()
        .await
        .map_err(|e| format!("{}: {e}", servers[0]))?;
    let ingest_s = t0.elapsed().as_secs_f64();
    if !r.status().is_success() {
        let status = r.status();
        let text = r.text().await.unwrap_or_default();
        return Err(format!(
            "{}: ingest: {status}: {}",
            servers[0],
            super::token::error_message(text.as_bytes())
        ));
    }
    let report: serde_json::Value = r.json().await.map_err(|e| e.to_string())?;
    let id = report["id"]
        .as_str()
        .ok_or(format!("ingest answered no id: {report}"))?
        .to_string();
    let seconds = args.seconds.max(2);
    let (urls, take) = (servers.clone(), id.clone());
    let url: Arc<UrlOf> = Arc::new(move |c: usize, s: usize| {
        format!(
            "{}/v1/takes/{take}/frames?t0={s}&t1={}&format=f32",
            urls[c % urls.len()],
            s + 1
        )
    });
    let result = hammer(&client, url, seconds - 1, args.clients, args.requests)
        .await
        .map(|r| {
            let mut run = Run::default();
            run.add(r);
            run.summary()
        });
    // Leave no take behind (an admin token may delete it; others leave it, and say so).
    let deleted = client
        .delete(format!("{}/v1/takes/{id}", servers[servers.len() - 1]))
        .send()
        .await
        .is_ok_and(|r| r.status().is_success());
    let (p50, p99, rps) = result?;
    let mut out = format!(
        "take: {frames} frames × {} points at {} fps ({} s) through {}: stored as {} at ratio \
         {:.1}; ingest {:.2} s\n\n| 1-s ranges over {} servers, round-robin ({} clients, {} \
         requests) | p50 ms | p99 ms | req/s |\n|---|---:|---:|---:|\n| {} | {p50:.3} | {p99:.3} | \
         {rps:.0} |\n",
        args.points,
        args.fps,
        args.seconds,
        servers[0],
        report["codec"].as_str().unwrap_or("?"),
        report["ratio"].as_f64().unwrap_or(0.0),
        ingest_s,
        servers.len(),
        args.clients,
        args.requests,
        servers.join(", ")
    );
    if !deleted {
        out +=
            &format!("\n(take {id} was left in library loadtest: the token may not delete it)\n");
    }
    Ok(out)
}
