//! Shared test set-up: a fresh store on each backend.
//!
//! SQLite: a new file in a temporary folder. Postgres: a new database on the server named by
//! `MOCAP_TEST_PG_URL` (`.ci/run` sets it), dropped afterwards. When that variable is set
//! and the server cannot be reached, the test fails; when it is unset, the Postgres half is
//! skipped with a message on stderr.

#![allow(dead_code)]

use std::time::Duration;

use mocapstore::http::{Application, Config};
use mocapstore::limits::Limits;
use mocapstore::store::Store;
use serde_json::Value;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

pub struct TestStore {
    pub name: &'static str,
    pub store: Store,
    pub url: String,
    cleanup: Cleanup,
}

enum Cleanup {
    Dir(std::path::PathBuf),
    Database { admin_url: String, db: String },
}

impl TestStore {
    /// The database URL (for the CLI, which opens the store itself).
    pub fn url(&self) -> &str {
        &self.url
    }

    /// Open the store again (a stopped server closes its pool), as a restarted server would.
    pub async fn reopen(&mut self) {
        self.store = Store::open(&self.url).await.expect("reopen the store");
    }

    pub async fn finish(self) {
        self.store.close().await;
        match self.cleanup {
            Cleanup::Dir(d) => {
                let _ = std::fs::remove_dir_all(d);
            }
            Cleanup::Database { admin_url, db } => {
                if let Ok(admin) = sqlx::PgPool::connect(&admin_url).await {
                    let _ = sqlx::query(&format!("DROP DATABASE IF EXISTS {db} WITH (FORCE)"))
                        .execute(&admin)
                        .await;
                    admin.close().await;
                }
            }
        }
    }
}

fn unique(prefix: &str) -> String {
    format!("{prefix}_{}", uuid::Uuid::now_v7().simple())
}

/// A database not opened yet (no tables): its URL, and how to remove it after.
pub struct Unopened {
    pub name: &'static str,
    pub url: String,
    cleanup: Cleanup,
}

impl Unopened {
    /// Open it as a store (which migrates it).
    pub async fn open(self) -> TestStore {
        TestStore {
            store: Store::open(&self.url)
                .await
                .unwrap_or_else(|e| panic!("open {}: {e}", self.name)),
            name: self.name,
            url: self.url,
            cleanup: self.cleanup,
        }
    }
}

/// SQLite always, Postgres when configured: databases with no tables yet.
pub async fn all_unopened() -> Vec<Unopened> {
    let mut v = vec![unopened_sqlite()];
    if let Some(pg) = unopened_postgres().await {
        v.push(pg);
    }
    v
}

fn unopened_sqlite() -> Unopened {
    let dir = std::env::temp_dir().join(unique("mocapstore-test"));
    std::fs::create_dir_all(&dir).unwrap();
    Unopened {
        name: "sqlite",
        url: format!("sqlite://{}", dir.join("store.db").display()),
        cleanup: Cleanup::Dir(dir),
    }
}

pub async fn sqlite() -> TestStore {
    unopened_sqlite().open().await
}

pub async fn postgres() -> Option<TestStore> {
    Some(unopened_postgres().await?.open().await)
}

async fn unopened_postgres() -> Option<Unopened> {
    let Ok(admin_url) = std::env::var("MOCAP_TEST_PG_URL") else {
        eprintln!("MOCAP_TEST_PG_URL is not set: skipping the Postgres half of this test");
        return None;
    };
    let admin = sqlx::PgPool::connect(&admin_url)
        .await
        .unwrap_or_else(|e| panic!("MOCAP_TEST_PG_URL={admin_url} is set but unreachable: {e}"));
    let db = unique("mocapstore_test");
    sqlx::query(&format!("CREATE DATABASE {db}"))
        .execute(&admin)
        .await
        .expect("create test database");
    admin.close().await;
    let (base, _) = admin_url.rsplit_once('/').expect("URL has a database path");
    Some(Unopened {
        name: "postgres",
        url: format!("{base}/{db}"),
        cleanup: Cleanup::Database { admin_url, db },
    })
}

/// SQLite always, Postgres when configured.
pub async fn all() -> Vec<TestStore> {
    let mut v = vec![sqlite().await];
    if let Some(pg) = postgres().await {
        v.push(pg);
    }
    v
}

/// A server-sent event stream, read event by event.
pub struct Events {
    response: reqwest::Response,
    buffer: String,
}

impl Events {
    pub fn new(response: reqwest::Response) -> Events {
        Events {
            response,
            buffer: String::new(),
        }
    }

    /// The next event's name and JSON data; None when the response ends. Fails the test if
    /// none comes within 10 s.
    pub async fn next(&mut self) -> Option<(String, Value)> {
        loop {
            if let Some(cut) = self.buffer.find("\n\n") {
                let block: String = self.buffer.drain(..cut + 2).collect();
                let mut name = "message".to_string();
                let mut data = String::new();
                for line in block.lines() {
                    if let Some(n) = line.strip_prefix("event:") {
                        name = n.trim().to_string();
                    } else if let Some(d) = line.strip_prefix("data:") {
                        data.push_str(d.strip_prefix(' ').unwrap_or(d));
                    }
                }
                if data.is_empty() {
                    continue; // a keep-alive comment
                }
                return Some((name, serde_json::from_str(&data).unwrap()));
            }
            let chunk = tokio::time::timeout(Duration::from_secs(10), self.response.chunk())
                .await
                .expect("an event within 10 s")
                .unwrap()?;
            self.buffer.push_str(std::str::from_utf8(&chunk).unwrap());
        }
    }
}

/// The real server on 127.0.0.1:0 over a test store, and a client for it.
pub struct Server {
    pub base: String,
    /// Where `/metrics` is served without a token, if the config asked for it.
    pub metrics_addr: Option<std::net::SocketAddr>,
    pub client: reqwest::Client,
    stop: tokio::sync::oneshot::Sender<()>,
    task: tokio::task::JoinHandle<()>,
}

pub async fn start(store: Store, max_body_bytes: usize) -> Server {
    start_with(
        store,
        Config {
            limits: Limits {
                upload_bytes: max_body_bytes as u64,
                ..Limits::default()
            },
            ..Config::default()
        },
    )
    .await
}

/// The real server with `config` (its address and database are the test's).
pub async fn start_with(store: Store, config: Config) -> Server {
    // Server-side errors (500s carry no detail) show in a failing test's output.
    let _ = tracing_subscriber::fmt()
        .with_env_filter("warn")
        .with_test_writer()
        .try_init();
    let config = Config {
        listen: "127.0.0.1:0".into(),
        database_url: String::new(),
        decoded_cache_mib: 64,
        ..config
    };
    let app = Application::with_store(store, config).await.unwrap();
    let base = format!("http://{}", app.local_addr());
    let metrics_addr = app.metrics_addr();
    let (stop, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        app.run_until(async {
            let _ = rx.await;
        })
        .await
        .unwrap();
    });
    Server {
        base,
        metrics_addr,
        client: reqwest::Client::new(),
        stop,
        task,
    }
}

impl Server {
    pub async fn stop(self) {
        let _ = self.stop.send(());
        let _ = self.task.await;
    }

    pub async fn post(&self, query: &str, body: Vec<u8>) -> (u16, Value) {
        let r = self
            .client
            .post(format!("{}/v1/takes?{query}", self.base))
            .body(body)
            .send()
            .await
            .unwrap();
        let status = r.status().as_u16();
        (status, r.json().await.unwrap_or(Value::Null))
    }

    /// POST a JSON body to `path`; the status, the `Location` header and the JSON answer.
    pub async fn post_json(&self, path: &str, body: &Value) -> (u16, Option<String>, Value) {
        let r = self
            .client
            .post(format!("{}{path}", self.base))
            .json(body)
            .send()
            .await
            .unwrap();
        let status = r.status().as_u16();
        let location = r
            .headers()
            .get("location")
            .map(|v| v.to_str().unwrap().to_string());
        (status, location, r.json().await.unwrap_or(Value::Null))
    }

    /// GET `path` as JSON.
    pub async fn get_json(&self, path: &str) -> (u16, Value) {
        let (status, _, body) = self.get(path).await;
        (status, serde_json::from_slice(&body).unwrap_or(Value::Null))
    }

    /// DELETE `path`; the status.
    pub async fn delete(&self, path: &str) -> u16 {
        self.client
            .delete(format!("{}{path}", self.base))
            .send()
            .await
            .unwrap()
            .status()
            .as_u16()
    }

    pub async fn get(&self, path: &str) -> (u16, reqwest::header::HeaderMap, Vec<u8>) {
        let r = self
            .client
            .get(format!("{}{path}", self.base))
            .send()
            .await
            .unwrap();
        let status = r.status().as_u16();
        let headers = r.headers().clone();
        (status, headers, r.bytes().await.unwrap().to_vec())
    }
}

/// Wait for a background job to finish: one long poll (the server answers when the job ends,
/// within its 600 s cap), no sleeping loop and no deadline of the test's own.
pub async fn wait_for_job(srv: &Server, location: &str) -> Value {
    let (status, job) = srv.get_json(&format!("{location}?wait_s=600")).await;
    assert_eq!(status, 200, "{job}");
    assert_ne!(
        job["state"], "running",
        "job {location} still running after 600 s: {job}"
    );
    job
}

/// [`wait_for_job`] on a server that needs tokens, as `secret`.
pub async fn wait_for_job_as(srv: &Server, secret: &str, location: &str) -> Value {
    let r = srv
        .client
        .get(format!("{}{location}?wait_s=600", srv.base))
        .bearer_auth(secret)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let job: Value = r.json().await.unwrap();
    assert_eq!(job["state"], "succeeded", "{job}");
    job
}

/// Metrics from one read of `/metrics` (on the metrics address if the server has one: a
/// server with tokens serves `/metrics` to admins only), by name.
pub async fn metrics(srv: &Server) -> std::collections::HashMap<String, u64> {
    let body = match srv.metrics_addr {
        Some(a) => reqwest::get(format!("http://{a}/metrics"))
            .await
            .unwrap()
            .bytes()
            .await
            .unwrap()
            .to_vec(),
        None => srv.get("/metrics").await.2,
    };
    String::from_utf8(body)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| {
            let (k, v) = l.split_once(' ')?;
            Some((k.to_string(), v.trim().parse::<f64>().ok()? as u64))
        })
        .collect()
}

/// Wait until the server has seen `requests` requests besides this wait's own reads of
/// `/metrics`, answered or dropped every one, and holds none of their bodies. Polled, at most
/// 30 s: a server that never settles fails the test rather than hang it.
pub async fn settled(srv: &Server, requests: u64) {
    for poll in 1..=600u64 {
        let m = metrics(srv).await;
        let get = |k: &str| *m.get(k).unwrap_or_else(|| panic!("no {k} in /metrics"));
        // This read is counted as started and is the one request in flight.
        if get("mocapstore_http_requests_started_total") >= requests + poll
            && get("mocapstore_http_requests_in_flight") <= 1
            && get("mocapstore_request_body_bytes_held") == 0
        {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    panic!("the server did not settle");
}

/// The status line and body of a raw HTTP exchange: `head` is sent, then `body`, and the
/// answer read until the server closes or `Content-Length` is met.
pub async fn raw(base: &str, head: &str, body: &[u8]) -> (u16, String, TcpStream) {
    let addr = base.trim_start_matches("http://");
    let mut s = TcpStream::connect(addr).await.unwrap();
    s.write_all(head.as_bytes()).await.unwrap();
    s.write_all(body).await.unwrap();
    let mut buf = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        let n = tokio::time::timeout(Duration::from_secs(30), s.read(&mut chunk))
            .await
            .expect("the server answers")
            .unwrap();
        buf.extend_from_slice(&chunk[..n]);
        let text = String::from_utf8_lossy(&buf).to_string();
        if let Some((h, b)) = text.split_once("\r\n\r\n") {
            let len = h
                .lines()
                .find_map(|l| {
                    l.to_ascii_lowercase()
                        .strip_prefix("content-length:")
                        .map(|v| v.trim().parse::<usize>().unwrap())
                })
                .unwrap_or(0);
            if b.len() >= len || n == 0 {
                let status = h[9..12].parse().unwrap();
                return (status, text, s);
            }
        }
        if n == 0 {
            panic!("connection closed without an answer: {text}");
        }
    }
}

/// A gauge from `/metrics`.
pub async fn gauge(srv: &Server, name: &str) -> u64 {
    metrics(srv).await[name]
}

/// Wait until no answer holds or reserves bytes: a client can have read an answer's last byte
/// a moment before the server drops the stream that held it, so a test that reads the
/// gauges right after a body would race the server's release.
pub async fn answers_released(srv: &Server) {
    for _ in 0..600 {
        let m = metrics(srv).await;
        if m["mocapstore_answer_bytes_held"] == 0 && m["mocapstore_answer_bytes_reserved"] == 0 {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("answers still hold bytes 30 s after their bodies were read");
}

/// Poll `f` until it holds, at most `tries` times 50 ms apart.
pub async fn eventually<F: std::future::Future<Output = bool>>(
    tries: usize,
    mut f: impl FnMut() -> F,
) {
    for _ in 0..tries {
        if f().await {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("condition never held");
}

/// A token made on the store itself, its secret.
pub async fn token(store: &Store, name: &str, scope: &str, libraries: Option<&[&str]>) -> String {
    mocapstore::service::access::create_token(
        store,
        mocapstore::service::access::TokenRequest {
            name: name.into(),
            scope: scope.into(),
            libraries: libraries.map(|l| l.iter().map(|s| s.to_string()).collect()),
            expires_at: None,
        },
    )
    .await
    .unwrap()
    .secret
}

/// The Python with the independent readers the tests check files against (py-c3d), from
/// `MOCAP_TEST_PYTHON` (`scripts/pyenv` makes it; `.ci/run` sets it). Unset: `None`, and
/// the test says it skips that part. Set but unusable: the test fails.
pub fn python() -> Option<std::path::PathBuf> {
    let Ok(p) = std::env::var("MOCAP_TEST_PYTHON") else {
        eprintln!("MOCAP_TEST_PYTHON is not set: skipping the independent reader's half (scripts/pyenv makes one)");
        return None;
    };
    let p = std::path::PathBuf::from(p);
    let ok = std::process::Command::new(&p)
        .args(["-c", "import c3d, numpy"])
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ok,
        "MOCAP_TEST_PYTHON={} is set but cannot import c3d and numpy",
        p.display()
    );
    Some(p)
}

/// Runs `scripts/{name}` with the test Python and `args`: the JSON of the last line it
/// prints (the scripts print one JSON line; a failure panics with what they said).
pub fn script<S: AsRef<std::ffi::OsStr>>(
    python: &std::path::Path,
    name: &str,
    args: impl IntoIterator<Item = S>,
) -> Value {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts")
        .join(name);
    let o = std::process::Command::new(python)
        .arg(path)
        .args(args)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    serde_json::from_str(text.trim().lines().last().unwrap_or(""))
        .unwrap_or_else(|_| panic!("{name} said {text} {}", String::from_utf8_lossy(&o.stderr)))
}

/// A JSON array of strings (point or node names), as `&str`s.
pub fn strings(v: &Value) -> Vec<&str> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect()
}

/// [`mocapstore`] on the blocking pool, for a test whose server runs on this runtime.
pub async fn mocapstore_beside(args: Vec<String>) -> std::process::Output {
    tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_mocapstore"))
            .args(&args)
            .output()
            .expect("binary runs")
    })
    .await
    .unwrap()
}

/// Run the `mocapstore` binary: success, stdout, stderr.
pub fn mocapstore(args: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mocapstore"))
        .args(args)
        .output()
        .expect("binary runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Joint positions of a take's `/frames?unit=m` answer (`ours`, at `fps` from `t0` s)
/// against scripts/gltf-eval.py's evaluation of a glTF (`theirs`) at each of its key times
/// that falls on one of the take's frames, node matched by name: how many were compared,
/// and the farthest apart (m).
pub fn against_gltf_eval(ours: &Value, theirs: &Value, fps: f64, t0: f64) -> (usize, f64) {
    let nodes = strings(&theirs["nodes"]);
    let names = strings(&ours["points"]);
    let at = |v: &Value| {
        [
            v[0].as_f64().unwrap(),
            v[1].as_f64().unwrap(),
            v[2].as_f64().unwrap(),
        ]
    };
    let (mut compared, mut worst) = (0usize, 0.0f64);
    for (k, time) in theirs["times"].as_array().unwrap().iter().enumerate() {
        let f = (time.as_f64().unwrap() - t0) * fps;
        if (f - f.round()).abs() > 1e-3 {
            continue;
        }
        let f = f.round() as usize;
        for (i, name) in names.iter().enumerate() {
            let j = nodes
                .iter()
                .position(|n| n == name)
                .unwrap_or_else(|| panic!("{name} is not a node of the glTF"));
            // A gap of ours (null) is not compared: formats show it each their own way.
            if ours["frames"][f][i][0].is_null() {
                continue;
            }
            let (a, b) = (at(&ours["frames"][f][i]), at(&theirs["positions"][k][j]));
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            worst = worst.max(d);
            compared += 1;
        }
    }
    (compared, worst)
}

/// The Khronos validator's report of a file: (errors, the first messages).
pub fn validate(modules: &std::path::Path, file: &std::path::Path) -> Value {
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/gltf/validate.mjs");
    let o = std::process::Command::new("node")
        .arg(script)
        .arg(file)
        .env("GLTF_NODE_MODULES", modules)
        .output()
        .unwrap();
    serde_json::from_slice(o.stdout.trim_ascii()).unwrap_or_else(|_| {
        panic!(
            "validate.mjs said {} {}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    })
}

/// The Node modules of the independent glTF tools, when the tests are given them.
pub fn node_modules() -> Option<std::path::PathBuf> {
    std::env::var_os("MOCAP_TEST_NODE_MODULES").map(std::path::PathBuf::from)
}
