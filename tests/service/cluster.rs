//! Several servers on one database (issue 37), as separate processes of the built binary, so
//! that one can be killed (`SIGKILL`) mid-job: jobs are rows every server sees, identical
//! requests share one job, and a job whose server died is run again by another.

use crate::common;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use serde_json::{json, Value};

/// A `mocapstore serve` process on port 0 (its address read from its log), killed when
/// dropped.
struct Process {
    child: Child,
    base: String,
    log: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
}

impl Process {
    fn start(database_url: &str, args: &[&str]) -> Process {
        let mut child = Command::new(env!("CARGO_BIN_EXE_mocapstore"))
            .args([
                "serve",
                "--listen",
                "127.0.0.1:0",
                "--database-url",
                database_url,
            ])
            .args(args)
            .env("NO_COLOR", "1")
            .env("RUST_LOG", "info")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start the server");
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let address = loop {
            let line = lines.next().expect("the server logs its address").unwrap();
            if let Some((_, rest)) = line.split_once("address=") {
                break rest.split_whitespace().next().unwrap().to_string();
            }
        };
        // Read the rest of its log (kept for a failing test), or a full pipe would stop it.
        let log = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let keep = log.clone();
        std::thread::spawn(move || {
            for line in lines.map_while(Result::ok) {
                keep.lock().unwrap().push(line);
            }
        });
        Process {
            child,
            base: format!("http://{address}"),
            log,
        }
    }

    /// Its log's warnings and errors so far.
    fn complaints(&self) -> String {
        let log = self.log.lock().unwrap();
        let bad = log
            .iter()
            .filter(|l| l.contains("WARN") || l.contains("ERROR"));
        bad.cloned().collect::<Vec<_>>().join("\n")
    }

    fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        self.kill();
    }
}

async fn post_json(base: &str, path: &str, body: &Value) -> (u16, Value) {
    let r = reqwest::Client::new()
        .post(format!("{base}{path}"))
        .json(body)
        .send()
        .await
        .unwrap();
    (r.status().as_u16(), r.json().await.unwrap_or(Value::Null))
}

async fn get_json(base: &str, path: &str) -> (u16, Value) {
    let r = reqwest::get(format!("{base}{path}")).await.unwrap();
    (r.status().as_u16(), r.json().await.unwrap_or(Value::Null))
}

#[tokio::test(flavor = "multi_thread")]
async fn jobs_are_seen_shared_and_taken_over_by_every_server() {
    for t in common::all().await {
        let url = t.url().to_string();
        let servers: Vec<Process> = (0..3)
            .map(|_| Process::start(&url, &["--job-lease-s", "5"]))
            .collect();
        let base = |i: usize| servers[i % 3].base.clone();
        // Takes of one layout, stored through each server in turn.
        for i in 0..6u64 {
            let m = walker(1_200, 12, 120.0, i + 1, 0.0);
            let r = reqwest::Client::new()
                .post(format!(
                    "{}/v1/takes?library=lab&name=t{i}",
                    base(i as usize)
                ))
                .body(formats::write(&m, Format::Json).unwrap())
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 201, "{}", t.name);
        }

        // A job started on one server is the same job on the others; an identical request
        // sent to them while it runs gets it, not a second job.
        let request = json!({"library": "lab", "max_iterations": 400, "sparsity": 4});
        let (status, job) = post_json(&base(0), "/v1/bases", &request).await;
        assert_eq!(status, 202, "{}: {job}", t.name);
        let id = job["id"].as_str().unwrap().to_string();
        for i in [1, 2] {
            let (status, again) = post_json(&base(i), "/v1/bases", &request).await;
            assert_eq!(status, 202, "{again}\n{}", servers[i].complaints());
            // The job trains for hundreds of milliseconds: these come while it runs.
            assert_eq!(
                again["id"],
                id.as_str(),
                "{}: identical requests, one job",
                t.name
            );
        }
        let (status, done) = get_json(&base(2), &format!("/v1/jobs/{id}?wait_s=120")).await;
        assert_eq!(status, 200);
        eprintln!(
            "{}: the job took {} ms",
            t.name,
            done["finished_at"].as_i64().unwrap() - done["created_at"].as_i64().unwrap()
        );
        assert_eq!(done["state"], "succeeded", "{}: {done}", t.name);
        assert_eq!(done["attempts"], 1);
        for i in 0..3 {
            let (_, seen) = get_json(&base(i), &format!("/v1/jobs/{id}")).await;
            assert_eq!(
                seen["state"], "succeeded",
                "server {i} sees the job finished"
            );
            assert_eq!(seen["result"]["id"], done["result"]["id"]);
            let (_, list) = get_json(&base(i), "/v1/jobs").await;
            assert!(list["items"]
                .as_array()
                .unwrap()
                .iter()
                .any(|j| j["id"] == id.as_str()));
        }
        let (_, bases) = get_json(&base(1), "/v1/bases").await;
        assert_eq!(
            bases["items"].as_array().unwrap().len(),
            1,
            "one job, one basis"
        );

        // The server running a job dies: after its lease another runs the job again.
        let mut servers = servers;
        let slow = json!({"library": "lab", "max_iterations": 400, "sparsity": 5});
        let (status, job) = post_json(&servers[0].base, "/v1/bases", &slow).await;
        assert_eq!(status, 202, "{job}");
        let id = job["id"].as_str().unwrap().to_string();
        servers[0].kill();
        let (_, done) = get_json(&servers[1].base, &format!("/v1/jobs/{id}?wait_s=300")).await;
        assert_eq!(done["state"], "succeeded", "{}: {done}", t.name);
        assert_eq!(
            done["attempts"], 2,
            "{}: run again after its server died: {done}",
            t.name
        );
        eprintln!(
            "{}: the job took {} ms with a server killed",
            t.name,
            done["finished_at"].as_i64().unwrap() - done["created_at"].as_i64().unwrap()
        );
        let (_, on_other) = get_json(&servers[2].base, &format!("/v1/jobs/{id}")).await;
        assert_eq!(on_other["result"]["id"], done["result"]["id"]);
        drop(servers);
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// `/readyz` says whether the database answers (what a balancer polls); `/healthz` only that
/// the process does.
#[tokio::test(flavor = "multi_thread")]
async fn ready_while_the_database_answers() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        let (status, _, body) = srv.get("/readyz").await;
        assert_eq!(
            (status, body.as_slice()),
            (200, &b"ready"[..]),
            "{}",
            t.name
        );
        // The database goes away (here: the server's pool is closed under it).
        t.store.close().await;
        let (status, h, body) = srv.get("/readyz").await;
        assert_eq!(status, 503, "{}", t.name);
        assert!(h.contains_key("retry-after"));
        let v: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(v["error"]["code"], "busy");
        let (status, _, _) = srv.get("/healthz").await;
        assert_eq!(status, 200, "alive, not ready");
        srv.stop().await;
    }
}

/// A TCP proxy the test owns between a server and Postgres: cutting it is the database
/// going away (every connection closed, new ones refused) without touching the shared
/// Postgres server.
struct Cuttable {
    addr: std::net::SocketAddr,
    cut: tokio::sync::watch::Sender<bool>,
}

impl Cuttable {
    async fn to(target: std::net::SocketAddr) -> Cuttable {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let (cut, watch) = tokio::sync::watch::channel(false);
        tokio::spawn(async move {
            loop {
                let Ok((mut client, _)) = listener.accept().await else {
                    return;
                };
                if *watch.borrow() {
                    continue; // refused: dropped at once
                }
                let mut watch = watch.clone();
                tokio::spawn(async move {
                    let Ok(mut server) = tokio::net::TcpStream::connect(target).await else {
                        return;
                    };
                    tokio::select! {
                        _ = tokio::io::copy_bidirectional(&mut client, &mut server) => {}
                        _ = watch.wait_for(|c| *c) => {}
                    }
                });
            }
        });
        Cuttable { addr, cut }
    }

    /// A proxy before the Postgres at `url`, and the URL that goes through it.
    async fn before(url: &str) -> (Cuttable, String) {
        let (head, rest) = url.split_once("://").unwrap();
        let (auth, hostpath) = rest.rsplit_once('@').map_or(("", rest), |(a, h)| (a, h));
        let (host, path) = hostpath.split_once('/').unwrap();
        let target: std::net::SocketAddr = tokio::net::lookup_host(host)
            .await
            .unwrap()
            .find(|a| a.is_ipv4())
            .unwrap();
        let proxy = Cuttable::to(target).await;
        let at = if auth.is_empty() {
            String::new()
        } else {
            format!("{auth}@")
        };
        let proxied = format!("{head}://{at}{}/{path}", proxy.addr);
        (proxy, proxied)
    }

    fn set(&self, cut: bool) {
        self.cut.send_replace(cut);
    }
}

/// Postgres cut off under ingests and reads for several seconds: every request ends (none
/// hangs) as a success or a 503 with `Retry-After`, never a 500; the server serves again
/// by itself within seconds of the database's return; nothing half-written is stored.
#[tokio::test(flavor = "multi_thread")]
async fn a_database_outage_is_503s_and_the_server_recovers_by_itself() {
    let Some(pg) = common::postgres().await else {
        return;
    };
    let (proxy, proxied) = Cuttable::before(pg.url()).await;
    let store = mocapstore::store::Store::open(&proxied).await.unwrap();
    let srv = common::start(store, 8 << 20).await;
    let client = reqwest::Client::builder()
        .timeout(Duration::from_secs(20))
        .build()
        .unwrap();
    let (status, _, _) = srv.get("/readyz").await;
    assert_eq!(status, 200);
    let first = walker(120, 6, 60.0, 1, 0.0);
    let r = client
        .post(format!("{}/v1/takes?codec=quant&name=first", srv.base))
        .body(formats::write(&first, Format::Json).unwrap())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let known: Value = r.json().await.unwrap();
    let known = known["id"].as_str().unwrap().to_string();

    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut workers = Vec::new();
    for w in 0..4u64 {
        let (client, base, stop, known) = (
            client.clone(),
            srv.base.clone(),
            stop.clone(),
            known.clone(),
        );
        workers.push(tokio::spawn(async move {
            // Status, Retry-After, an ingest; and the slowest answer.
            let mut seen: Vec<(u16, bool, bool)> = Vec::new();
            let mut slowest = Duration::ZERO;
            let mut n = 0u64;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                n += 1;
                let ingest = w.is_multiple_of(2);
                let req = if ingest {
                    let m = walker(60, 6, 60.0, 100 * w + n, 0.0);
                    client
                        .post(format!("{base}/v1/takes?codec=quant&library=outage"))
                        .body(formats::write(&m, Format::Json).unwrap())
                } else if n.is_multiple_of(2) {
                    client.get(format!("{base}/v1/takes/{known}/frames?format=f32"))
                } else {
                    client.get(format!("{base}/v1/takes?library=outage"))
                };
                let asked = std::time::Instant::now();
                let r = req
                    .send()
                    .await
                    .expect("every request is answered (none hangs)");
                slowest = slowest.max(asked.elapsed());
                let status = r.status().as_u16();
                let retry = r.headers().contains_key("retry-after");
                let body = r.bytes().await.unwrap_or_default();
                if status == 503 && !retry {
                    eprintln!(
                        "503 without Retry-After: {}",
                        String::from_utf8_lossy(&body)
                    );
                }
                seen.push((status, retry, ingest));
                if status == 503 {
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            }
            (seen, slowest)
        }));
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    proxy.set(true);
    tokio::time::sleep(Duration::from_secs(8)).await;
    let (status, _, _) = srv.get("/readyz").await;
    assert_eq!(status, 503, "not ready while the database is away");
    proxy.set(false);
    let back = std::time::Instant::now();
    loop {
        let (status, _, _) = srv.get("/readyz").await;
        if status == 200 {
            break;
        }
        assert!(
            back.elapsed() < Duration::from_secs(15),
            "ready again within seconds"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    eprintln!(
        "ready again {} ms after the database",
        back.elapsed().as_millis()
    );
    tokio::time::sleep(Duration::from_secs(2)).await;
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let mut all = Vec::new();
    let mut slowest = Duration::ZERO;
    for w in workers {
        let (seen, slow) = w.await.unwrap();
        all.extend(seen);
        slowest = slowest.max(slow);
    }
    // A request waits for a connection 5 s at most (the pool's acquire timeout), then 503.
    assert!(
        slowest < Duration::from_secs(10),
        "fails fast: the slowest took {slowest:?}"
    );
    let count = |f: &dyn Fn(&(u16, bool, bool)) -> bool| all.iter().filter(|s| f(s)).count();
    let created = count(&|s| s.0 == 201);
    let refused_ingests = count(&|s| s.0 == 503 && s.2);
    eprintln!(
        "outage: {} requests, {} succeeded, {} refused with 503, the slowest {slowest:?}",
        all.len(),
        count(&|s| s.0 < 300),
        count(&|s| s.0 == 503)
    );
    let odd: Vec<_> = all
        .iter()
        .filter(|s| !matches!(s.0, 200 | 201 | 503))
        .collect();
    assert!(odd.is_empty(), "only successes and 503s: {odd:?}");
    assert!(
        all.iter().all(|s| s.0 != 503 || s.1),
        "every 503 says when to retry"
    );
    assert!(count(&|s| s.0 == 503) > 0, "the outage was seen");
    // The last requests, after the database came back, succeeded.
    assert!(
        all.iter().rev().take(4).all(|s| s.0 < 300),
        "served again: {:?}",
        &all[all.len() - 4..]
    );
    // Nothing half-written: every stored take reads back whole; an ingest answered 503
    // may have committed as the connection dropped (its answer lost), no more.
    let (status, stats) = srv.get_json("/v1/stats?library=outage").await;
    assert_eq!(status, 200);
    let stored = stats["total"]["takes"].as_u64().unwrap() as usize;
    assert!(
        created <= stored && stored <= created + refused_ingests,
        "{created} created, {stored} stored"
    );
    srv.stop().await;
    let (ok, out, err) = common::mocapstore(&["verify", "--database-url", pg.url()]);
    assert!(ok, "verify: {out}\n{err}");
}

/// `loadtest --server A --server B` reads one take through every server, round-robin.
#[tokio::test(flavor = "multi_thread")]
async fn loadtest_spreads_its_clients_over_the_servers() {
    let t = common::sqlite().await;
    let a = common::start(t.store.clone(), 64 << 20).await;
    let b = common::start(t.store.clone(), 64 << 20).await;
    let servers = format!("{},{}", a.base, b.base);
    let out = tokio::task::spawn_blocking(move || {
        common::mocapstore(&[
            "loadtest",
            "--server",
            &servers,
            "--seconds",
            "4",
            "--points",
            "8",
            "--clients",
            "4",
            "--requests",
            "40",
        ])
    })
    .await
    .unwrap();
    assert!(out.0, "{}\n{}", out.1, out.2);
    assert!(out.1.contains("over 2 servers"), "{}", out.1);
    for srv in [&a, &b] {
        let m = common::metrics(srv).await;
        assert!(
            m["mocapstore_decoded_frames_total"] >= 20 * 100,
            "each served its half"
        );
    }
    a.stop().await;
    b.stop().await;
}

/// A live stream outlives a database outage shorter than its lease: appends refused
/// meanwhile (503) are sent again, numbered, and the take holds every frame once.
#[tokio::test(flavor = "multi_thread")]
async fn a_stream_keeps_its_frames_through_a_database_outage() {
    let Some(pg) = common::postgres().await else {
        return;
    };
    let (proxy, proxied) = Cuttable::before(pg.url()).await;
    let store = mocapstore::store::Store::open(&proxied).await.unwrap();
    let srv = common::start(store, 8 << 20).await;
    let (status, _, s) = srv
        .post_json(
            "/v1/streams",
            &json!({"name": "through", "fps": 60, "points": 2}),
        )
        .await;
    assert_eq!(status, 201, "{s}");
    let id = s["id"].as_str().unwrap().to_string();
    const FRAMES: usize = 900;
    let batch = |from: usize, n: usize| json!({"frames": (from..from + n).map(|f| vec![f as f64, 0.0, 0.0, 1.0, 1.0, 1.0]).collect::<Vec<_>>()});
    let mut received = 0usize;
    let mut refused = 0usize;
    // The most frames taken but not yet stored: chunks held while the database was away.
    let mut held = 0usize;
    let started = std::time::Instant::now();
    let mut cut = false;
    while received < FRAMES {
        // The database goes away a second in, for 4 s (the lease is a minute).
        let t = started.elapsed();
        if !cut && t > Duration::from_secs(1) {
            proxy.set(true);
            cut = true;
        }
        if cut && t > Duration::from_secs(5) {
            proxy.set(false);
        }
        let n = 6.min(FRAMES - received);
        let (status, _, r) = srv
            .post_json(
                &format!("/v1/streams/{id}/frames?first={received}"),
                &batch(received, n),
            )
            .await;
        match status {
            200 => {
                received = r["frames_received"].as_u64().unwrap() as usize;
                let committed = r["frames_committed"].as_u64().unwrap() as usize;
                held = held.max(received - committed);
            }
            503 => refused += 1,
            other => panic!("append: {other} {r}"),
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    proxy.set(false);
    let take = loop {
        let (status, _, r) = srv
            .post_json(&format!("/v1/streams/{id}/finish"), &json!({}))
            .await;
        match status {
            200 => break r,
            503 => tokio::time::sleep(Duration::from_millis(200)).await,
            other => panic!("finish: {other} {r}"),
        }
    };
    eprintln!(
        "stream through an outage: {refused} appends refused, at most {held} frames held, \
         {} frames",
        take["frames"]
    );
    assert!(
        held > 60,
        "chunks (60 frames) were held while the database was away: {held}"
    );
    let (status, _, body) = srv.get(&format!("/v1/takes/{id}/frames")).await;
    assert_eq!(status, 200);
    let v: Value = serde_json::from_slice(&body).unwrap();
    let frames = v["frames"].as_array().unwrap();
    assert_eq!(frames.len(), FRAMES, "every frame once");
    for (f, frame) in frames.iter().enumerate() {
        let x = frame[0][0].as_f64().unwrap();
        assert!((x - f as f64).abs() <= 1.0, "frame {f} holds {x}");
    }
    srv.stop().await;
}

/// What a round-robin producer's run through several servers met.
#[derive(Default, Debug)]
struct Tally {
    requests: usize,
    ok: usize,
    /// 503s while the killed owner's lease ran.
    unavailable: usize,
    /// 409s that said where to send from (after the handover).
    resend: usize,
}

/// Append frames `first..first + n` (numbered) through `base`.
async fn append_numbered(
    base: &str,
    id: &str,
    first: usize,
    n: usize,
    frame: &impl Fn(usize) -> Vec<f64>,
) -> (u16, Value) {
    let frames: Vec<Vec<f64>> = (first..first + n).map(frame).collect();
    post_json(
        base,
        &format!("/v1/streams/{id}/frames?first={first}"),
        &json!({ "frames": frames }),
    )
    .await
}

/// A stream sent through three servers in turn codes as one stream on the server that
/// opened it (the others forward its appends and its watchers); when that server is
/// killed, the next append after its lease, through another, takes the stream over: the
/// frames it had accepted and never committed are counted exactly, the producer sends them
/// again, and the take holds every frame once. Reads, stats and deletes agree on every
/// server.
#[tokio::test(flavor = "multi_thread")]
async fn a_stream_goes_through_any_server_and_outlives_its_server() {
    const POINTS: usize = 4;
    const BEFORE: usize = 130; // 4 chunks of 30 committed, 10 frames pending at the kill
    const TOTAL: usize = 240;
    let frame = |f: usize| -> Vec<f64> {
        (0..POINTS * 3)
            .map(|k| 100.0 * ((f as f64) * 0.05 + k as f64).sin() + k as f64 * 10.0)
            .collect()
    };
    for t in common::all().await {
        let url = t.url().to_string();
        let mut servers: Vec<Process> = (0..3)
            .map(|_| Process::start(&url, &["--stream-lease-s", "3"]))
            .collect();
        let bases: Vec<String> = servers.iter().map(|s| s.base.clone()).collect();
        let mut tally = Tally::default();

        let (status, info) = post_json(
            &bases[0],
            "/v1/streams",
            &json!({"name": "roundrobin", "fps": 60, "points": POINTS,
                    "chunk_seconds": 0.5, "max_error_mm": 0.5}),
        )
        .await;
        assert_eq!(status, 201, "{}: {info}", t.name);
        let id = info["id"].as_str().unwrap().to_string();

        // A watcher on the third server sees the frames the first codes.
        let mut events = reqwest::get(format!("{}/v1/streams/{id}/events", bases[2]))
            .await
            .unwrap();
        assert_eq!(events.status(), 200);

        // Appends of 13 frames, round-robin: every one answered by the owner.
        let mut sent = 0;
        let mut i = 0;
        while sent < BEFORE {
            let n = 13.min(BEFORE - sent);
            let (status, r) = append_numbered(&bases[i % 3], &id, sent, n, &frame).await;
            tally.requests += 1;
            assert_eq!(
                status,
                200,
                "{}: append through server {}: {r}",
                t.name,
                i % 3
            );
            tally.ok += 1;
            sent += n;
            assert_eq!(r["frames_received"], sent, "{r}");
            i += 1;
        }
        let mut seen = String::new();
        while !seen.contains("event: frames") {
            let chunk = tokio::time::timeout(Duration::from_secs(10), events.chunk())
                .await
                .expect("the watcher hears of the appends")
                .unwrap()
                .expect("the event stream stays open");
            seen.push_str(&String::from_utf8_lossy(&chunk));
        }
        let (_, state) = get_json(&bases[1], &format!("/v1/streams/{id}")).await;
        assert_eq!(
            (
                state["frames_received"].as_u64(),
                state["frames_committed"].as_u64()
            ),
            (Some(BEFORE as u64), Some(120)),
            "{}: {state}",
            t.name
        );

        // The owner dies with 10 frames accepted and not committed.
        servers[0].kill();
        let mut at = sent;
        let lost = loop {
            let (status, r) = append_numbered(&bases[1 + i % 2], &id, at, 10, &frame).await;
            tally.requests += 1;
            i += 1;
            match status {
                503 => {
                    tally.unavailable += 1;
                    assert!(tally.unavailable < 100, "{}: no takeover: {r}", t.name);
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
                409 => {
                    // Numbered appends: the new owner says where to send from.
                    tally.resend += 1;
                    let msg = r["error"]["message"].as_str().unwrap();
                    assert!(msg.contains("send from frame 120"), "{msg}");
                    assert!(msg.contains("10 frames were lost"), "{msg}");
                    let (_, state) = get_json(&bases[2], &format!("/v1/streams/{id}")).await;
                    at = state["frames_received"].as_u64().unwrap() as usize;
                    break state["frames_lost"].as_u64().unwrap();
                }
                other => panic!("{}: append after the kill: {other} {r}", t.name),
            }
        };
        assert_eq!(
            (lost, at),
            (10, 120),
            "{}: the lost frames, exactly",
            t.name
        );

        // The producer sends them again, and goes on through both servers left.
        while at < TOTAL {
            let n = 13.min(TOTAL - at);
            let (status, r) = append_numbered(&bases[1 + i % 2], &id, at, n, &frame).await;
            tally.requests += 1;
            assert_eq!(status, 200, "{}: {r}", t.name);
            tally.ok += 1;
            at += n;
            i += 1;
        }
        let (status, take) =
            post_json(&bases[2], &format!("/v1/streams/{id}/finish"), &json!({})).await;
        tally.requests += 1;
        assert_eq!(status, 200, "{}: {take}", t.name);
        tally.ok += 1;
        assert_eq!(take["frames"], TOTAL, "{}: {take}", t.name);
        assert_eq!(take["meta"]["frames_lost"], 10, "{take}");
        assert_eq!(take["meta"]["handovers"][0]["frame"], 120, "{take}");
        assert_eq!(take["meta"]["handovers"][0]["frames_lost"], 10, "{take}");
        eprintln!(
            "{}: stream through three servers, owner killed: {tally:?}",
            t.name
        );

        // The take as sent, within its bound, read from either server left; stats agree.
        for base in &bases[1..] {
            let (status, v) = get_json(base, &format!("/v1/takes/{id}/frames")).await;
            assert_eq!(status, 200);
            let got = v["frames"].as_array().unwrap();
            assert_eq!(got.len(), TOTAL);
            for (f, row) in got.iter().enumerate() {
                let want = frame(f);
                for p in 0..POINTS {
                    let d: f64 = (0..3)
                        .map(|k| (row[p][k].as_f64().unwrap() - want[p * 3 + k]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    assert!(d <= 0.5 + 1e-6, "{}: frame {f} point {p}: {d} mm", t.name);
                }
            }
        }
        let (_, s1) = get_json(&bases[1], "/v1/stats").await;
        let (_, s2) = get_json(&bases[2], "/v1/stats").await;
        assert_eq!(s1, s2, "{}", t.name);
        drop(servers.remove(0));
        let (ok, out, err) = common::mocapstore(&["verify", "--database-url", &url]);
        assert!(ok, "{}: verify: {out}\n{err}", t.name);
        let r = reqwest::Client::new()
            .delete(format!("{}/v1/takes/{id}", bases[1]))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 204);
        let (status, _) = get_json(&bases[2], &format!("/v1/takes/{id}")).await;
        assert_eq!(
            status, 404,
            "a take deleted on one server is gone on the others"
        );
        drop(servers);
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// `streamtest --server A,B` spreads each stream's requests over both servers; the one
/// that did not open a stream forwards its appends to the one that did.
#[tokio::test(flavor = "multi_thread")]
async fn streamtest_spreads_its_requests_over_the_servers() {
    let t = common::sqlite().await;
    let a = common::start(t.store.clone(), 64 << 20).await;
    let b = common::start(t.store.clone(), 64 << 20).await;
    let servers = format!("{},{}", a.base, b.base);
    let out = tokio::task::spawn_blocking(move || {
        common::mocapstore(&[
            "streamtest",
            "--server",
            &servers,
            "--seconds",
            "4",
            "--live-seconds",
            "1",
            "--points",
            "8",
            "--fps",
            "60",
        ])
    })
    .await
    .unwrap();
    assert!(out.0, "{}\n{}", out.1, out.2);
    assert!(out.1.contains("over 2 servers"), "{}", out.1);
    let m = common::metrics(&b).await;
    assert!(
        m["mocapstore_stream_requests_forwarded_total"] >= 4,
        "the second server forwarded its share: {m:?}"
    );
    let (_, list) = a.get_json("/v1/takes").await;
    assert_eq!(
        list["items"].as_array().unwrap().len(),
        0,
        "the streams were deleted after: {list}"
    );
    a.stop().await;
    b.stop().await;
}
