//! Access control: every route × every kind of caller gives the documented status, on both
//! backends; secrets never reach the database, the audit log or the server's log; a server
//! without tokens stays on loopback; cross-origin writes are refused; rate limits answer 429
//! and recover.

use crate::common;
use common::token;

use std::collections::BTreeSet;
use std::time::Duration;

use mocapstore::http::Config;
use mocapstore::limits::Limits;
use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use mocapstore::service::access::{self, TokenRequest};
use mocapstore::store::Store;
use reqwest::Method;
use serde_json::{json, Value};

/// The callers of the matrix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Who {
    Nobody,
    Read,
    Write,
    Admin,
    /// A write token limited to another library than the takes'.
    WrongLibrary,
    Revoked,
    Expired,
}

const EVERYONE: [Who; 7] = [
    Who::Nobody,
    Who::Read,
    Who::Write,
    Who::Admin,
    Who::WrongLibrary,
    Who::Revoked,
    Who::Expired,
];

struct Secrets {
    read: String,
    write: String,
    admin: String,
    wrong: String,
    revoked: String,
    expired: String,
}

impl Secrets {
    fn of(&self, who: Who) -> Option<&str> {
        match who {
            Who::Nobody => None,
            Who::Read => Some(&self.read),
            Who::Write => Some(&self.write),
            Who::Admin => Some(&self.admin),
            Who::WrongLibrary => Some(&self.wrong),
            Who::Revoked => Some(&self.revoked),
            Who::Expired => Some(&self.expired),
        }
    }

    fn all(&self) -> [&str; 6] {
        [
            &self.read,
            &self.write,
            &self.admin,
            &self.wrong,
            &self.revoked,
            &self.expired,
        ]
    }
}

async fn tokens(store: &Store) -> Secrets {
    let expired = access::create_token(
        store,
        TokenRequest {
            name: "expired".into(),
            scope: "admin".into(),
            libraries: None,
            expires_at: Some(now_ms() + 1_500),
        },
    )
    .await
    .unwrap()
    .secret;
    let s = Secrets {
        read: token(store, "reader", "read", Some(&["lab"])).await,
        write: token(store, "writer", "write", Some(&["lab"])).await,
        admin: token(store, "admin", "admin", None).await,
        wrong: token(store, "elsewhere", "write", Some(&["elsewhere"])).await,
        revoked: token(store, "revoked", "admin", None).await,
        expired,
    };
    access::revoke_token(store, "revoked").await.unwrap();
    // Let the expiry pass.
    tokio::time::sleep(std::time::Duration::from_millis(1_600)).await;
    s
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_millis() as i64
}

/// One request as a caller; the status and the JSON answer (if any).
async fn call(
    srv: &common::Server,
    secret: Option<&str>,
    method: Method,
    path: &str,
    body: Body,
) -> (u16, Value) {
    let mut rb = srv.client.request(method, format!("{}{path}", srv.base));
    if let Some(s) = secret {
        rb = rb.bearer_auth(s);
    }
    rb = match body {
        Body::None => rb,
        Body::Json(v) => rb.json(&v),
        Body::Bytes(b) => rb.body(b),
    };
    let r = rb.send().await.unwrap();
    let status = r.status().as_u16();
    // An event stream lasts as long as its stream: its status is the answer.
    let events = r
        .headers()
        .get("content-type")
        .is_some_and(|t| t.as_bytes().starts_with(b"text/event-stream"));
    if events {
        return (status, Value::Null);
    }
    let bytes = r.bytes().await.unwrap();
    (
        status,
        serde_json::from_slice(&bytes).unwrap_or(Value::Null),
    )
}

#[derive(Clone)]
enum Body {
    None,
    Json(Value),
    Bytes(Vec<u8>),
}

fn take_bytes(seed: u64) -> Vec<u8> {
    formats::write(&walker(60, 4, 60.0, seed, 0.0), Format::Json).unwrap()
}

/// A take in library `lab`, stored by the admin; its id.
async fn new_take(srv: &common::Server, admin: &str, seed: u64) -> String {
    let (status, v) = call(
        srv,
        Some(admin),
        Method::POST,
        "/v1/takes?library=lab&codec=quant&max_error_mm=1",
        Body::Bytes(take_bytes(seed)),
    )
    .await;
    assert_eq!(status, 201, "{v}");
    v["id"].as_str().unwrap().to_string()
}

/// An open stream in library `lab`; its id.
async fn new_stream(srv: &common::Server, admin: &str) -> String {
    let (status, v) = call(
        srv,
        Some(admin),
        Method::POST,
        "/v1/streams",
        Body::Json(json!({"fps": 60.0, "points": 4, "library": "lab"})),
    )
    .await;
    assert_eq!(status, 201, "{v}");
    v["id"].as_str().unwrap().to_string()
}

/// The scope a route needs, and the status it answers a caller it lets through.
struct Case {
    method: Method,
    /// The route as `openapi.yaml` names it.
    route: &'static str,
    scope: &'static str,
    /// Whether a library-limited token outside `lab` is refused (the route touches a take
    /// of `lab`).
    in_lab: bool,
    ok: u16,
}

fn cases() -> Vec<Case> {
    let c = |method: Method, route, scope, in_lab, ok| Case {
        method,
        route,
        scope,
        in_lab,
        ok,
    };
    vec![
        c(Method::GET, "/metrics", "admin", false, 200),
        c(Method::GET, "/v1/takes", "read", false, 200),
        c(Method::POST, "/v1/takes", "write", true, 201),
        c(Method::GET, "/v1/takes/{id}", "read", true, 200),
        c(Method::PATCH, "/v1/takes/{id}", "write", true, 200),
        c(Method::DELETE, "/v1/takes/{id}", "admin", true, 204),
        c(Method::GET, "/v1/takes/{id}/frames", "read", true, 200),
        c(Method::GET, "/v1/takes/{id}/errors", "read", true, 200),
        // The matrix's take is no C3D: no analog channels, no parameters (409).
        c(Method::GET, "/v1/takes/{id}/analog", "read", true, 409),
        // Nor has it model outputs (409).
        c(Method::GET, "/v1/takes/{id}/outputs", "read", true, 409),
        c(Method::GET, "/v1/takes/{id}/parameters", "read", true, 409),
        // Motion like a take of the lab's: to another library's token it is not there.
        c(Method::GET, "/v1/takes/{id}/similar", "read", true, 200),
        c(Method::POST, "/v1/search", "read", true, 200),
        c(Method::GET, "/v1/stats", "read", false, 200),
        c(Method::GET, "/v1/export", "read", false, 200),
        c(Method::GET, "/v1/motion-stats", "read", false, 200),
        // Statistics of a take of the lab named by id: to another library's token it is not
        // there.
        c(Method::POST, "/v1/motion-stats", "read", true, 200),
        // A batch naming a take of the lab: to another library's token it is not there.
        c(Method::GET, "/v1/ranges", "read", true, 200),
        c(Method::GET, "/v1/bases", "read", false, 200),
        c(Method::POST, "/v1/bases", "admin", false, 400),
        c(Method::GET, "/v1/bases/{id}", "read", false, 404),
        c(Method::DELETE, "/v1/bases/{id}", "admin", false, 404),
        c(Method::GET, "/v1/jobs", "read", false, 200),
        c(Method::GET, "/v1/jobs/{id}", "read", false, 404),
        c(Method::GET, "/v1/skeletons", "read", false, 200),
        // An empty body: the scope is checked before it is read.
        c(Method::POST, "/v1/skeletons", "write", false, 400),
        c(Method::GET, "/v1/skeletons/{id}", "read", false, 404),
        c(Method::DELETE, "/v1/skeletons/{id}", "admin", false, 404),
        c(Method::GET, "/v1/skeletons/{id}/map", "read", false, 404),
        c(Method::POST, "/v1/streams", "write", true, 201),
        c(Method::GET, "/v1/streams/{id}", "read", true, 200),
        c(Method::GET, "/v1/streams/{id}/events", "read", true, 200),
        c(Method::POST, "/v1/streams/{id}/frames", "write", true, 200),
        c(Method::POST, "/v1/streams/{id}/finish", "write", true, 200),
        c(Method::GET, "/v1/tokens", "admin", false, 200),
        c(Method::POST, "/v1/tokens", "admin", false, 201),
        c(Method::DELETE, "/v1/tokens/{id}", "admin", false, 404),
        c(Method::GET, "/v1/audit", "admin", false, 200),
    ]
}

/// What `who` should get from `case`: the documented status.
fn expected(case: &Case, who: Who) -> u16 {
    let rank = |s: &str| match s {
        "read" => 1,
        "write" => 2,
        _ => 3,
    };
    let has = match who {
        Who::Nobody | Who::Revoked | Who::Expired => return 401,
        Who::Read => 1,
        Who::Write | Who::WrongLibrary => 2,
        Who::Admin => 3,
    };
    if has < rank(case.scope) {
        return 403;
    }
    if who == Who::WrongLibrary && case.in_lab {
        // A take of another library answers as one that does not exist; naming another
        // library for a new one is refused.
        let names_a_take = case.route.contains("{id}")
            || case.route == "/v1/ranges"
            || (case.method == Method::POST && case.route == "/v1/motion-stats")
            || (case.method == Method::POST && case.route == "/v1/search");
        return if names_a_take { 404 } else { 403 };
    }
    case.ok
}

/// The concrete request of a case, with fresh objects where a call uses one up.
async fn request(srv: &common::Server, admin: &str, case: &Case, n: u64) -> (String, Body) {
    let take = || async { new_take(srv, admin, n).await };
    // A take with a body (roles), which search compares by.
    let dancer = || async {
        let body = mocapstore::motion::synthetic::dancer_bvh(60, 30.0, n, 4).into_bytes();
        let (status, v) = call(
            srv,
            Some(admin),
            Method::POST,
            "/v1/takes?library=lab&codec=quant",
            Body::Bytes(body),
        )
        .await;
        assert_eq!(status, 201, "{v}");
        v["id"].as_str().unwrap().to_string()
    };
    let stream = || async { new_stream(srv, admin).await };
    match (case.method.as_str(), case.route) {
        ("POST", "/v1/takes") => (
            "/v1/takes?library=lab&codec=quant&max_error_mm=1".into(),
            Body::Bytes(take_bytes(n)),
        ),
        ("GET", "/v1/takes/{id}") => (format!("/v1/takes/{}", take().await), Body::None),
        ("PATCH", _) => (
            format!("/v1/takes/{}", take().await),
            Body::Json(json!({"tags": ["seen"]})),
        ),
        ("DELETE", "/v1/takes/{id}") => (format!("/v1/takes/{}", take().await), Body::None),
        ("GET", "/v1/takes/{id}/frames") => (
            format!(
                "/v1/takes/{}/frames?start=0&end=10&format=f32",
                take().await
            ),
            Body::None,
        ),
        ("GET", "/v1/ranges") => {
            let id = take().await;
            (
                format!("/v1/ranges?ranges={id}:0-10,{id}:5-15&format=f32"),
                Body::None,
            )
        }
        ("GET", "/v1/takes/{id}/similar") => (
            format!("/v1/takes/{}/similar?k=3", dancer().await),
            Body::None,
        ),
        ("POST", "/v1/search") => (
            format!("/v1/search?take={}&t0=0&t1=1", dancer().await),
            Body::None,
        ),
        ("POST", "/v1/motion-stats") => (
            "/v1/motion-stats".into(),
            Body::Json(json!({"ids": [take().await]})),
        ),
        ("GET", "/v1/takes/{id}/errors") => {
            (format!("/v1/takes/{}/errors", take().await), Body::None)
        }
        ("GET", "/v1/takes/{id}/analog") => {
            (format!("/v1/takes/{}/analog", take().await), Body::None)
        }
        ("GET", "/v1/takes/{id}/outputs") => {
            (format!("/v1/takes/{}/outputs", take().await), Body::None)
        }
        ("GET", "/v1/takes/{id}/parameters") => {
            (format!("/v1/takes/{}/parameters", take().await), Body::None)
        }
        ("POST", "/v1/bases") => (
            "/v1/bases".into(),
            Body::Json(json!({"library": "no such library"})),
        ),
        ("GET" | "DELETE", "/v1/bases/{id}") => ("/v1/bases/none".into(), Body::None),
        ("GET", "/v1/jobs/{id}") => ("/v1/jobs/none".into(), Body::None),
        ("POST", "/v1/skeletons") => ("/v1/skeletons".into(), Body::None),
        ("GET" | "DELETE", "/v1/skeletons/{id}") => ("/v1/skeletons/none".into(), Body::None),
        ("GET", "/v1/skeletons/{id}/map") => ("/v1/skeletons/none/map?to=smpl".into(), Body::None),
        ("POST", "/v1/streams") => (
            "/v1/streams".into(),
            Body::Json(json!({"fps": 60.0, "points": 4, "library": "lab"})),
        ),
        ("GET", "/v1/streams/{id}") => (format!("/v1/streams/{}", stream().await), Body::None),
        ("GET", "/v1/streams/{id}/events") => {
            (format!("/v1/streams/{}/events", stream().await), Body::None)
        }
        ("POST", "/v1/streams/{id}/frames") => (
            format!("/v1/streams/{}/frames", stream().await),
            Body::Bytes(vec![0u8; 4 * 3 * 4 * 2]),
        ),
        ("POST", "/v1/streams/{id}/finish") => {
            (format!("/v1/streams/{}/finish", stream().await), Body::None)
        }
        ("POST", "/v1/tokens") => (
            "/v1/tokens".into(),
            Body::Json(json!({"name": format!("made-{n}"), "scope": "read"})),
        ),
        ("DELETE", "/v1/tokens/{id}") => ("/v1/tokens/none".into(), Body::None),
        (_, route) => (route.to_string(), Body::None),
    }
}

/// Open streams left by the matrix, finished so that none holds a slot.
async fn finish_streams(srv: &common::Server, admin: &str, opened: &[String]) {
    for id in opened {
        call(
            srv,
            Some(admin),
            Method::POST,
            &format!("/v1/streams/{id}/finish"),
            Body::None,
        )
        .await;
    }
}

#[tokio::test]
async fn every_route_answers_every_caller_as_documented() {
    for t in common::all().await {
        let secrets = tokens(&t.store).await;
        // Hundreds of calls in a few seconds: a rate limit that never refuses (it has its own
        // test), but is on, so every route goes through it.
        let srv = common::start_with(
            t.store.clone(),
            Config {
                limits: Limits {
                    upload_bytes: 8 << 20,
                    requests_per_s: 1_000_000,
                    request_burst: 1_000_000,
                    ..Limits::default()
                },
                ..Config::default()
            },
        )
        .await;
        let admin = secrets.admin.clone();
        let mut failures = Vec::new();
        let mut n = 0u64;
        for case in cases() {
            for who in EVERYONE {
                n += 1;
                let (path, body) = request(&srv, &admin, &case, n).await;
                let (status, answer) =
                    call(&srv, secrets.of(who), case.method.clone(), &path, body).await;
                // Streams opened for (or by) this call are finished: none keeps a slot.
                let opened = match path.strip_prefix("/v1/streams/") {
                    Some(rest) => rest.split('/').next().map(str::to_string),
                    None => answer["id"]
                        .as_str()
                        .filter(|_| case.route == "/v1/streams")
                        .map(str::to_string),
                };
                finish_streams(&srv, &admin, opened.as_slice()).await;
                let want = expected(&case, who);
                if status != want {
                    failures.push(format!(
                        "{} {} as {who:?}: {status}, documented {want}: {answer}",
                        case.method, case.route
                    ));
                }
                if matches!(status, 401 | 403) {
                    let code = answer["error"]["code"].as_str().unwrap_or("");
                    if !["unauthorized", "forbidden"].contains(&code) {
                        failures.push(format!("{} {path}: error body {answer}", case.method));
                    }
                }
            }
        }
        assert!(failures.is_empty(), "{}:\n{}", t.name, failures.join("\n"));

        // A limited token's listing shows only its libraries.
        let (_, mine) = call(
            &srv,
            Some(&secrets.read),
            Method::GET,
            "/v1/takes",
            Body::None,
        )
        .await;
        let (_, none) = call(
            &srv,
            Some(&secrets.wrong),
            Method::GET,
            "/v1/takes",
            Body::None,
        )
        .await;
        assert!(!mine["items"].as_array().unwrap().is_empty(), "{mine}");
        assert!(none["items"].as_array().unwrap().is_empty(), "{none}");
        let (_, stats) = call(
            &srv,
            Some(&secrets.wrong),
            Method::GET,
            "/v1/stats",
            Body::None,
        )
        .await;
        assert_eq!(stats["total"]["takes"], 0, "{stats}");

        // The audit log names who did what, refusals included, and holds no secret.
        let (status, log) = call(
            &srv,
            Some(&admin),
            Method::GET,
            "/v1/audit?limit=1000",
            Body::None,
        )
        .await;
        assert_eq!(status, 200);
        let entries = log.as_array().unwrap();
        assert!(entries
            .iter()
            .any(|e| e["action"] == "DELETE /v1/takes/{id}"
                && e["status"] == 204
                && e["token_name"] == "admin"));
        assert!(entries
            .iter()
            .any(|e| e["action"] == "DELETE /v1/takes/{id}"
                && e["status"] == 403
                && e["token_name"] == "writer"));
        assert!(entries
            .iter()
            .any(|e| e["status"] == 401 && e["token_name"].is_null()));
        let text = log.to_string();
        for s in secrets.all() {
            assert!(!text.contains(s), "a secret in the audit log");
        }
        srv.stop().await;
        assert_no_secret_stored(&t, &secrets.all()).await;
        t.finish().await;
    }
}

/// No secret in any table (every column of every row, as text), nor in SQLite's files.
async fn assert_no_secret_stored(t: &common::TestStore, secrets: &[&str]) {
    let store = Store::open(t.url()).await.unwrap();
    let dump: Vec<String> = match &store {
        Store::Sqlite(_) => {
            // The database's own bytes: every table, index and page not yet checkpointed.
            let mut all = Vec::new();
            let path = t.url().trim_start_matches("sqlite://").to_string();
            for suffix in ["", "-wal"] {
                if let Ok(bytes) = std::fs::read(format!("{path}{suffix}")) {
                    all.push(String::from_utf8_lossy(&bytes).into_owned());
                }
            }
            all
        }
        Store::Postgres(pool) => {
            let mut all = Vec::new();
            for table in ["tokens", "audit_log", "takes", "take_tags"] {
                let rows: Vec<String> =
                    sqlx::query_scalar(&format!("SELECT t::text FROM {table} t"))
                        .fetch_all(pool)
                        .await
                        .unwrap();
                all.extend(rows);
            }
            all
        }
    };
    assert!(!dump.is_empty(), "the dump read the database");
    for s in secrets {
        let hex_tail = &s[4..];
        assert!(
            !dump.iter().any(|d| d.contains(s) || d.contains(hex_tail)),
            "{}: a token secret is stored",
            t.name
        );
    }
    store.close().await;
}

#[tokio::test]
async fn without_tokens_the_server_stays_on_loopback_and_refuses_other_hosts() {
    let t = common::sqlite().await;
    let config = |listen: &str, open: bool| Config {
        listen: listen.into(),
        policy: mocapstore::http::auth::Policy {
            open_beyond_loopback: open,
            ..Default::default()
        },
        ..Config::default()
    };
    let refused =
        mocapstore::http::Application::with_store(t.store.clone(), config("0.0.0.0:0", false))
            .await
            .err()
            .expect("no tokens: refused");
    assert!(refused.contains("--insecure-no-auth"), "{refused}");
    assert!(
        mocapstore::http::Application::with_store(t.store.clone(), config("0.0.0.0:0", true))
            .await
            .is_ok(),
        "the operator may insist"
    );
    // On loopback without tokens: anyone, but only by a loopback name (DNS rebinding).
    let srv = common::start(t.store.clone(), 1 << 20).await;
    let r = srv
        .client
        .get(format!("{}/v1/takes", srv.base))
        .header("host", "evil.example")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 403);
    let (status, _, _) = srv.get("/v1/takes").await;
    assert_eq!(status, 200);
    // With a token, the same address may serve beyond loopback.
    token(&t.store, "ops", "admin", None).await;
    assert!(
        mocapstore::http::Application::with_store(t.store.clone(), config("0.0.0.0:0", false))
            .await
            .is_ok()
    );
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn cross_origin_writes_are_refused_unless_the_origin_is_allowed() {
    let t = common::sqlite().await;
    let srv = common::start_with(
        t.store.clone(),
        Config {
            policy: mocapstore::http::auth::Policy {
                allowed_origins: vec!["https://viewer.example".into()],
                ..Default::default()
            },
            ..Config::default()
        },
    )
    .await;
    let post = |origin: &'static str| {
        srv.client
            .post(format!("{}/v1/takes?codec=quant", srv.base))
            .header("origin", origin)
            .header("content-type", "text/plain")
            .body(take_bytes(1))
            .send()
    };
    let r = post("https://evil.example").await.unwrap();
    assert_eq!(r.status(), 403);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["error"]["code"], "cross_origin");
    let (_, list) = srv.get_json("/v1/takes").await;
    assert!(
        list["items"].as_array().unwrap().is_empty(),
        "nothing stored"
    );
    let r = post("https://viewer.example").await.unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(
        r.headers()["access-control-allow-origin"],
        "https://viewer.example"
    );
    // A preflight from the allowed origin is answered; one from elsewhere gets no grant.
    let pre = |origin: &'static str| {
        srv.client
            .request(Method::OPTIONS, format!("{}/v1/takes", srv.base))
            .header("origin", origin)
            .header("access-control-request-method", "POST")
            .header(
                "access-control-request-headers",
                "authorization,content-type",
            )
            .send()
    };
    let ok = pre("https://viewer.example").await.unwrap();
    assert_eq!(
        ok.headers()["access-control-allow-origin"],
        "https://viewer.example"
    );
    let no = pre("https://evil.example").await.unwrap();
    assert!(no.headers().get("access-control-allow-origin").is_none());
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn the_rate_limit_answers_429_with_retry_after_and_recovers() {
    let t = common::sqlite().await;
    let secret = token(&t.store, "busy", "read", None).await;
    let other = token(&t.store, "calm", "read", None).await;
    let srv = common::start_with(
        t.store.clone(),
        Config {
            limits: Limits {
                requests_per_s: 2,
                request_burst: 3,
                ..Limits::default()
            },
            ..Config::default()
        },
    )
    .await;
    // Routes with path parameters go through the limiter too (a take to read first).
    let writer = token(&t.store, "writer", "write", None).await;
    let (status, v) = call(
        &srv,
        Some(&writer),
        Method::POST,
        "/v1/takes?codec=quant",
        Body::Bytes(take_bytes(5)),
    )
    .await;
    assert_eq!(status, 201, "{v}");
    let frames = format!(
        "/v1/takes/{}/frames?start=0&end=5",
        v["id"].as_str().unwrap()
    );
    let (status, v) = call(&srv, Some(&other), Method::GET, &frames, Body::None).await;
    assert_eq!(status, 200, "{v}");
    let mut statuses = Vec::new();
    let mut retry = None;
    for _ in 0..6 {
        let r = srv
            .client
            .get(format!("{}/v1/stats", srv.base))
            .bearer_auth(&secret)
            .send()
            .await
            .unwrap();
        statuses.push(r.status().as_u16());
        if r.status() == 429 {
            retry = r.headers().get("retry-after").cloned();
            let v: Value = r.json().await.unwrap();
            assert_eq!(v["error"]["code"], "rate_limited");
        }
    }
    assert_eq!(&statuses[..3], &[200, 200, 200], "{statuses:?}");
    assert!(statuses[3..].contains(&429), "{statuses:?}");
    let wait: u64 = retry.unwrap().to_str().unwrap().parse().unwrap();
    assert!(wait >= 1);
    // Another token is not held back by this one.
    let (status, _) = call(&srv, Some(&other), Method::GET, "/v1/stats", Body::None).await;
    assert_eq!(status, 200);
    tokio::time::sleep(std::time::Duration::from_millis(1_100 * wait)).await;
    let (status, _) = call(&srv, Some(&secret), Method::GET, "/v1/stats", Body::None).await;
    assert_eq!(status, 200, "recovered");
    // Refusals count against their address: guessing secrets is slowed down too.
    let mut refused = Vec::new();
    for _ in 0..6 {
        let (status, _) = call(
            &srv,
            Some("mcs_guess"),
            Method::GET,
            "/v1/stats",
            Body::None,
        )
        .await;
        refused.push(status);
    }
    assert_eq!(&refused[..3], &[401, 401, 401], "{refused:?}");
    assert!(refused[3..].contains(&429), "{refused:?}");
    srv.stop().await;
    t.finish().await;
}

/// Every route of `openapi.yaml` is in the matrix, so a new route cannot go untested.
#[test]
fn the_matrix_covers_every_documented_route() {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/openapi.yaml")).unwrap();
    let spec: Value = serde_yaml_ng::from_str(&text).unwrap();
    let mut documented = BTreeSet::new();
    for (path, ops) in spec["paths"].as_object().unwrap() {
        for (method, op) in ops.as_object().unwrap() {
            if method == "parameters" || path == "/healthz" || path == "/readyz" {
                continue;
            }
            documented.insert(format!("{} {path}", method.to_uppercase()));
            let scope = op["x-scope"].as_str().unwrap_or("none");
            let case = cases()
                .into_iter()
                .find(|c| c.method.as_str().eq_ignore_ascii_case(method) && c.route == path);
            let case = case.unwrap_or_else(|| panic!("{method} {path} is not in the matrix"));
            assert_eq!(case.scope, scope, "{method} {path}: scope in openapi.yaml");
        }
    }
    assert_eq!(documented.len(), cases().len());
}

/// The operator's commands: create (secret shown once), list, revoke, audit; and a server
/// logging at trace level never prints a secret, valid or not.
#[tokio::test]
async fn token_commands_work_and_no_secret_reaches_the_server_log() {
    let t = common::sqlite().await;
    let db = t.url().to_string();
    let (ok, out, err) = common::mocapstore(&[
        "token",
        "create",
        "--scope",
        "write",
        "--name",
        "lab-writer",
        "--library",
        "lab",
        "--expires",
        "30d",
        "--database-url",
        &db,
    ]);
    assert!(ok, "{err}");
    let secret = out
        .lines()
        .find_map(|l| l.strip_prefix("secret, shown this once: "))
        .expect("the secret is printed")
        .to_string();
    assert!(secret.starts_with("mcs_") && secret.len() == 68, "{secret}");
    let (ok, out, _) = common::mocapstore(&[
        "token",
        "create",
        "--first",
        "--scope",
        "admin",
        "--name",
        "boot",
        "--database-url",
        &db,
    ]);
    assert!(
        ok && out.is_empty(),
        "--first creates nothing once a token exists: {out}"
    );
    let (ok, _, err) = common::mocapstore(&[
        "token",
        "create",
        "--scope",
        "admin",
        "--name",
        "x",
        "--library",
        "lab",
        "--database-url",
        &db,
    ]);
    assert!(!ok && err.contains("admin token"), "{err}");

    // Without tokens, `serve` on a non-loopback address refuses to start, and says why.
    let empty = common::sqlite().await;
    let (ok, _, err) = common::mocapstore(&[
        "serve",
        "--listen",
        "0.0.0.0:0",
        "--database-url",
        empty.url(),
    ]);
    assert!(
        !ok && err.contains("refusing to serve") && err.contains("--insecure-no-auth"),
        "{err}"
    );
    empty.finish().await;

    // The real binary, logging everything, asked with the secret and with a wrong one.
    // Port 0, the address read back from its log: no port found free here and bound
    // again by the child, which another process could take between.
    let log = std::env::temp_dir().join(format!(
        "mocapstore-auth-log-{}-{}.txt",
        std::process::id(),
        now_ms()
    ));
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_mocapstore"))
        .args(["serve", "--listen", "127.0.0.1:0", "--database-url", &db])
        .env("RUST_LOG", "trace")
        .env("NO_COLOR", "1")
        .stdout(std::fs::File::create(&log).unwrap())
        .stderr(std::fs::File::create(log.with_extension("err")).unwrap())
        .spawn()
        .unwrap();
    let mut address = None;
    for _ in 0..200 {
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        if let Some((_, rest)) = text.split_once("address=") {
            address = rest.split_whitespace().next().map(str::to_string);
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    let base = format!("http://{}", address.expect("the server logs its address"));
    let client = reqwest::Client::new();
    let mut up = false;
    for _ in 0..200 {
        if client.get(format!("{base}/healthz")).send().await.is_ok() {
            up = true;
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    assert!(up, "the server started");
    let wrong = format!("mcs_{}", "0".repeat(64));
    for s in [&secret, &wrong] {
        let _ = client
            .post(format!("{base}/v1/takes?library=lab&codec=quant"))
            .bearer_auth(s)
            .body(take_bytes(3))
            .send()
            .await
            .unwrap();
    }
    let r = client
        .get(format!("{base}/v1/takes"))
        .bearer_auth(&secret)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let _ = child.kill();
    let _ = child.wait();
    let text = std::fs::read_to_string(&log).unwrap_or_default()
        + &std::fs::read_to_string(log.with_extension("err")).unwrap_or_default();
    assert!(
        text.contains("/v1/takes"),
        "the log has the requests: {text}"
    );
    for s in [&secret, &wrong] {
        assert!(
            !text.contains(s.as_str()) && !text.contains(&s[4..]),
            "a secret in the log"
        );
    }

    let (ok, out, _) = common::mocapstore(&["token", "list", "--database-url", &db]);
    assert!(
        ok && out.contains("lab-writer") && out.contains("| write | lab |"),
        "{out}"
    );
    assert!(!out.contains(&secret[4..]));
    let (ok, out, _) =
        common::mocapstore(&["token", "revoke", "lab-writer", "--database-url", &db]);
    assert!(ok, "{out}");
    let (ok, _, err) =
        common::mocapstore(&["token", "revoke", "lab-writer", "--database-url", &db]);
    assert!(!ok && err.contains("not found"), "{err}");
    let (ok, out, _) = common::mocapstore(&["audit", "--database-url", &db]);
    assert!(ok, "{out}");
    assert!(
        out.contains("token revoke") && out.contains("token create"),
        "{out}"
    );
    assert!(
        out.contains("POST /v1/takes") && out.contains("| lab-writer |"),
        "{out}"
    );
    assert!(!out.contains(&secret[4..]));
    let _ = std::fs::remove_file(&log);
    let _ = std::fs::remove_file(log.with_extension("err"));
    t.finish().await;
}

/// Behind a trusted proxy the client's address (from `X-Forwarded-For`) is what anonymous
/// rate limits count, so two clients behind one proxy have their own; without
/// `--trusted-proxy` the header is anyone's to write, and ignored.
#[tokio::test]
async fn a_trusted_proxy_names_the_client_and_no_one_else_can() {
    let limits = Limits {
        requests_per_s: 1,
        request_burst: 2,
        ..Limits::default()
    };
    let open = mocapstore::http::auth::Policy {
        open_beyond_loopback: true,
        ..Default::default()
    };
    let statuses = |srv: &common::Server, from: &'static str| {
        let (client, url) = (srv.client.clone(), format!("{}/v1/stats", srv.base));
        async move {
            let mut got = Vec::new();
            for _ in 0..4 {
                let r = client
                    .get(&url)
                    .header("x-forwarded-for", from)
                    .send()
                    .await
                    .unwrap();
                got.push(r.status().as_u16());
            }
            got
        }
    };
    for trusted in [true, false] {
        let t = common::sqlite().await;
        let proxies = if trusted {
            vec!["127.0.0.1/32"]
        } else {
            vec![]
        };
        let srv = common::start_with(
            t.store.clone(),
            Config {
                limits,
                policy: open.clone(),
                trusted_proxies: mocapstore::http::proxy::TrustedProxies::parse(&proxies).unwrap(),
                ..Config::default()
            },
        )
        .await;
        let first = statuses(&srv, "203.0.113.1").await;
        assert!(first.contains(&429), "{trusted}: {first:?}");
        // Another client behind the proxy; then the first again, forging an entry before
        // the one the proxy appended.
        let second = statuses(&srv, "203.0.113.2").await;
        let forged = statuses(&srv, "203.0.113.9, 203.0.113.1").await;
        if trusted {
            assert_eq!(second[0], 200, "its own limit: {second:?}");
            assert_eq!(
                forged[0], 429,
                "a forged entry is not the client: {forged:?}"
            );
        } else {
            assert_eq!(second[0], 429, "one peer, one limit: {second:?}");
        }
        srv.stop().await;
    }
}

/// Revocation on running servers, two on one database (SQLite and Postgres): a token
/// revoked over HTTP is refused at once by the server that revoked it and within
/// [`TOKEN_CACHE`] by the other; one revoked with the CLI (on the database, no server told)
/// within [`TOKEN_CACHE`] by both. Each server had the token cached as good just before.
#[tokio::test]
async fn a_revoked_token_stops_at_once_here_and_within_the_cache_time_everywhere() {
    for t in common::all().await {
        let admin = token(&t.store, "admin", "admin", None).await;
        let a = common::start(t.store.clone(), 8 << 20).await;
        let b = common::start(t.store.clone(), 8 << 20).await;
        let client = reqwest::Client::new();
        let create = |name: &str| {
            let r = client
                .post(format!("{}/v1/tokens", a.base))
                .bearer_auth(&admin)
                .json(&serde_json::json!({"name": name, "scope": "read"}))
                .send();
            async move {
                let r = r.await.unwrap();
                assert_eq!(r.status(), 201);
                let v: serde_json::Value = r.json().await.unwrap();
                (
                    v["id"].as_str().unwrap().to_string(),
                    v["secret"].as_str().unwrap().to_string(),
                )
            }
        };

        // Over HTTP, on server a.
        let (id, secret) = create("victim").await;
        assert_eq!(status(&client, &a, &secret).await, 200, "{}", t.name);
        assert_eq!(status(&client, &b, &secret).await, 200, "{}", t.name);
        let r = client
            .delete(format!("{}/v1/tokens/{id}", a.base))
            .bearer_auth(&admin)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 204, "{}", t.name);
        assert_eq!(
            status(&client, &a, &secret).await,
            401,
            "{}: at once here",
            t.name
        );
        let took = refused_within(&client, "the other server", &b, &secret).await;
        eprintln!(
            "{}: revoked over HTTP, the other server refused it after {took:?}",
            t.name
        );
        let listed: serde_json::Value = client
            .get(format!("{}/v1/tokens", b.base))
            .bearer_auth(&admin)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        let row = listed
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["id"] == id.as_str())
            .unwrap()
            .clone();
        assert!(row["revoked_at"].is_i64(), "{row}");

        // With the CLI, on the database alone.
        let (_, secret) = create("victim-cli").await;
        assert_eq!(status(&client, &a, &secret).await, 200);
        assert_eq!(status(&client, &b, &secret).await, 200);
        let url = t.url().to_string();
        let (ok, out, err) = tokio::task::spawn_blocking(move || {
            common::mocapstore(&["token", "revoke", "victim-cli", "--database-url", &url])
        })
        .await
        .unwrap();
        assert!(ok, "{out}{err}");
        for (name, srv) in [("server a", &a), ("server b", &b)] {
            let took = refused_within(&client, name, srv, &secret).await;
            eprintln!(
                "{}: revoked with the CLI, {name} refused it after {took:?}",
                t.name
            );
        }
        a.stop().await;
        b.stop().await;
        t.finish().await;
    }
}

/// The status of a read with `secret` on `srv`.
async fn status(client: &reqwest::Client, srv: &common::Server, secret: &str) -> u16 {
    client
        .get(format!("{}/v1/takes", srv.base))
        .bearer_auth(secret)
        .send()
        .await
        .unwrap()
        .status()
        .as_u16()
}

/// How long until `srv` (called `name`) refuses `secret`, polled every 50 ms; it must within
/// the token cache time and a second.
async fn refused_within(
    client: &reqwest::Client,
    name: &str,
    srv: &common::Server,
    secret: &str,
) -> Duration {
    let started = std::time::Instant::now();
    loop {
        match status(client, srv, secret).await {
            401 => return started.elapsed(),
            200 => {}
            other => panic!("{name}: {other}"),
        }
        assert!(
            started.elapsed() <= mocapstore::limits::TOKEN_CACHE + Duration::from_secs(1),
            "{name} still takes a revoked token after {:?}",
            started.elapsed()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}
