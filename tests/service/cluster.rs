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
            .map(|_| Process::start(&url, &["--job-lease-s", "2"]))
            .collect();
        let base = |i: usize| servers[i % 3].base.clone();
        // Takes of one layout, stored through each server in turn.
        for i in 0..6u64 {
            let m = walker(1_200, 12, 120.0, i + 1, 0.0);
            let r = reqwest::Client::new()
                .post(format!(
                    "{}/v1/sequences?library=lab&name=t{i}",
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
