//! Finding motion by motion (issue 51): `/v1/search` and `/v1/takes/{id}/similar` find a
//! copy of a take at the very range the query was cut from, an uploaded clip as its stored
//! take, never the query's own range; a library-limited token's answers do not depend on
//! other libraries' takes; features are taken at ingest, again by the index job when a
//! take changes or has none, and go with a deleted take; two servers of one database give
//! the same answers.

use crate::common;

use serde_json::{json, Value};

use mocapstore::corpus;
use mocapstore::store::Store;

async fn ingest(srv: &common::Server, query: &str, body: Vec<u8>) -> String {
    let (status, v) = srv.post(query, body).await;
    assert_eq!(status, 201, "{query}: {v}");
    v["id"].as_str().unwrap().to_string()
}

/// Run `sql` on the test's database (the tests' own access to the rows).
async fn execute(store: &Store, sql: &str) -> u64 {
    match store {
        Store::Sqlite(pool) => sqlx::query(sql)
            .execute(pool)
            .await
            .unwrap()
            .rows_affected(),
        Store::Postgres(pool) => sqlx::query(sql)
            .execute(pool)
            .await
            .unwrap()
            .rows_affected(),
    }
}

async fn count(store: &Store, sql: &str) -> i64 {
    match store {
        Store::Sqlite(pool) => sqlx::query_scalar(sql).fetch_one(pool).await.unwrap(),
        Store::Postgres(pool) => sqlx::query_scalar(sql).fetch_one(pool).await.unwrap(),
    }
}

fn names(answer: &Value) -> Vec<String> {
    answer["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["name"].as_str().unwrap().to_string())
        .collect()
}

const FILES: [&str; 9] = [
    "dataset-1_walk_normal_001",
    "dataset-1_walk_happy_001",
    "dataset-1_walk_tired_001",
    "dataset-1_bow_normal_001",
    "dataset-1_bow_happy_001",
    "dataset-1_bow_tired_001",
    "dataset-1_dash_normal_001",
    "dataset-1_dash_happy_001",
    "dataset-1_dash_tired_001",
];

/// Bandai takes of three actions, one of them twice: a range of one copy finds the other
/// copy first, at the same seconds, with a score of about 0, then the takes of the same
/// action; the query's own range is never an answer; `per_take` gives runs that do not
/// overlap; an uploaded clip (a range of a file) finds its stored take at that range; the
/// answer says what it searched; the same answers from a second server of the database.
#[tokio::test(flavor = "multi_thread")]
async fn a_range_finds_its_copy_where_it_was_cut_and_its_action_next() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    for t in common::all().await {
        let one = common::start(t.store.clone(), 64 << 20).await;
        let file = |name: &str| std::fs::read(root.join(format!("bvh/bandai/{name}.bvh"))).unwrap();
        let mut ids = std::collections::HashMap::new();
        for name in FILES {
            let id = ingest(
                &one,
                &format!("name={name}&library=lab&codec=quant"),
                file(name),
            )
            .await;
            ids.insert(name.to_string(), id);
        }
        let copy = ingest(
            &one,
            "name=copy&library=lab&codec=quant",
            file("dataset-1_walk_happy_001"),
        )
        .await;
        let query = &ids["dataset-1_walk_happy_001"];
        let (status, a) = one
            .get_json(&format!("/v1/takes/{query}/similar?t0=1&t1=3&k=5"))
            .await;
        assert_eq!(status, 200, "{a}");
        assert_eq!(a["query"]["take"], query.as_str());
        assert_eq!(
            (a["query"]["t0"].as_f64(), a["query"]["t1"].as_f64()),
            (Some(1.0), Some(3.0))
        );
        assert_eq!(a["query"]["windows"], 3, "{a}");
        assert_eq!(a["searched"]["takes"], 10, "{a}");
        assert_eq!(a["searched"]["unindexed"], 0, "{a}");
        let first = &a["results"][0];
        assert_eq!(first["take"], copy.as_str(), "{a}");
        assert_eq!(
            (first["t0"].as_f64(), first["t1"].as_f64()),
            (Some(1.0), Some(3.0))
        );
        assert!(first["score"].as_f64().unwrap() < 1e-6, "{first}");
        // The same range in the take's own frames (30 fps, printed 0.0333333).
        assert_eq!(
            (first["start"].as_u64(), first["end"].as_u64()),
            (Some(30), Some(90))
        );
        // Then walks: the other two of the three.
        let found = names(&a);
        assert_eq!(found.len(), 5);
        let walks = found[1..3].iter().filter(|n| n.contains("_walk_")).count();
        assert_eq!(walks, 2, "{found:?}");
        // Scores ascend; the query's own range is not among the answers, and no take twice.
        let scores: Vec<f64> = a["results"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["score"].as_f64().unwrap())
            .collect();
        assert!(scores.windows(2).all(|w| w[0] <= w[1]), "{scores:?}");
        for r in a["results"].as_array().unwrap() {
            if r["take"] == query.as_str() {
                let (t0, t1) = (r["t0"].as_f64().unwrap(), r["t1"].as_f64().unwrap());
                assert!(t1 <= 1.0 || t0 >= 3.0, "its own range: {r}");
            }
        }
        let mut takes: Vec<&str> = a["results"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["take"].as_str().unwrap())
            .collect();
        takes.sort();
        takes.dedup();
        assert_eq!(takes.len(), 5);
        // Two runs of a take that do not overlap.
        let (_, two) = one
            .get_json(&format!(
                "/v1/takes/{query}/similar?t0=1&t1=2&k=2&per_take=2&name_prefix=copy"
            ))
            .await;
        let runs = two["results"].as_array().unwrap();
        assert_eq!(runs.len(), 2, "{two}");
        assert!(runs.iter().all(|r| r["take"] == copy.as_str()));
        let span = |r: &Value| (r["t0"].as_f64().unwrap(), r["t1"].as_f64().unwrap());
        let (x, y) = (span(&runs[0]), span(&runs[1]));
        assert!(x.1 <= y.0 || y.1 <= x.0, "{x:?} {y:?}");
        // Filters: labels none has, a library none is in.
        let (_, none) = one
            .get_json(&format!("/v1/takes/{query}/similar?label.style=x"))
            .await;
        assert_eq!(none["results"].as_array().unwrap().len(), 0, "{none}");
        assert_eq!(none["searched"]["takes"], 0);
        // The listing's other filters select what is searched: the query's skeleton takes
        // the takes whose records name it (Bandai's files come on more than one), its rate
        // and its length every take; another skeleton, a longer minimum, none.
        let (_, record) = one.get_json(&format!("/v1/takes/{query}")).await;
        let skeleton = record["skeleton"].as_str().unwrap().to_string();
        let mut same = 0;
        for id in ids.values().chain([&copy]) {
            let (_, r) = one.get_json(&format!("/v1/takes/{id}")).await;
            same += usize::from(r["skeleton"] == skeleton.as_str());
        }
        assert!(same >= 2, "the query and its copy");
        let all = a["searched"]["takes"].clone();
        for (filter, takes) in [
            (format!("skeleton={skeleton}"), json!(same)),
            ("skeleton=no-such-skeleton".to_string(), json!(0)),
            ("fps=30".to_string(), all.clone()),
            (
                "min_duration_s=0.1&max_duration_s=3600".to_string(),
                all.clone(),
            ),
            ("min_duration_s=3600".to_string(), json!(0)),
            ("tag=none-has-it".to_string(), json!(0)),
        ] {
            let (status, v) = one
                .get_json(&format!("/v1/takes/{query}/similar?t0=1&t1=3&{filter}"))
                .await;
            assert_eq!(status, 200, "{filter}: {v}");
            assert_eq!(v["searched"]["takes"], takes, "{filter}: {v}");
        }

        // An uploaded clip: a range of a file finds its stored take at that range.
        let r = one
            .client
            .post(format!(
                "{}/v1/search?t0=2&t1=4&k=3&name_prefix=dataset",
                one.base
            ))
            .body(file("dataset-1_dash_tired_001"))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        let clip: Value = r.json().await.unwrap();
        assert!(clip["query"].get("take").is_none(), "{clip}");
        let best = &clip["results"][0];
        assert_eq!(best["name"], "dataset-1_dash_tired_001", "{clip}");
        assert_eq!(
            (best["t0"].as_f64(), best["t1"].as_f64()),
            (clip["query"]["t0"].as_f64(), clip["query"]["t1"].as_f64())
        );
        assert_eq!(clip["query"]["t0"].as_f64(), Some(2.0), "{clip}");
        assert!(best["score"].as_f64().unwrap() < 0.05, "{best}");
        // The same with take= names the stored take.
        let dash = &ids["dataset-1_dash_tired_001"];
        let r = one
            .client
            .post(format!("{}/v1/search?take={dash}&t0=2&t1=4&k=3", one.base))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        let stored: Value = r.json().await.unwrap();
        assert_eq!(stored["query"]["windows"], clip["query"]["windows"]);

        // The CLI: the same first range, as a table; a clip that is not there, by name.
        let (ok, out, err) = common::mocapstore(&[
            "search", "--server", &one.base, "--take", query, "--t0", "1", "--t1", "3", "-k", "2",
        ]);
        assert!(ok, "{err}");
        let row = out.lines().nth(2).unwrap_or_default();
        assert!(
            row.contains(copy.as_str()) && row.contains("1.00") && row.contains("3.00"),
            "{out}"
        );
        let (ok, _, err) = common::mocapstore(&["search", "--server", &one.base, "/no/such.bvh"]);
        assert!(!ok && err.contains("/no/such.bvh"), "{err}");

        // What cannot be asked.
        for (path, want) in [
            (format!("/v1/takes/{query}/similar?k=0"), 400),
            (format!("/v1/takes/{query}/similar?k=101"), 400),
            (format!("/v1/takes/{query}/similar?per_take=0"), 400),
            (format!("/v1/takes/{query}/similar?t0=3&t1=2"), 400),
            (format!("/v1/takes/{query}/similar?t0=999"), 416),
            (format!("/v1/takes/{query}/similar?t0=inf"), 400),
            (format!("/v1/takes/{query}/similar?t0=1&t1=NaN"), 400),
            ("/v1/takes/no-such-take/similar".to_string(), 404),
        ] {
            let (status, v) = one.get_json(&path).await;
            assert_eq!(status, want, "{path}: {v}");
            assert!(v["error"]["message"].is_string(), "{path}: {v}");
        }
        for (query, body) in [
            ("", Vec::new()),
            ("take=x", b"BVH".to_vec()),
            ("", b"not motion".to_vec()),
        ] {
            let r = one
                .client
                .post(format!("{}/v1/search?{query}", one.base))
                .body(body)
                .send()
                .await
                .unwrap();
            assert!(r.status().is_client_error(), "{query}: {}", r.status());
        }

        // A second server of the same database answers the same.
        let two = common::start(t.store.clone(), 64 << 20).await;
        let (_, again) = two
            .get_json(&format!("/v1/takes/{query}/similar?t0=1&t1=3&k=5"))
            .await;
        assert_eq!(again, a);
        two.stop().await;
        one.stop().await;
        t.finish().await;
    }
}

/// Store Bandai take `name` (quant, for speed) in `library` with `token`; its id.
async fn put_bandai(
    srv: &common::Server,
    token: &str,
    root: &std::path::Path,
    name: &str,
    library: &str,
) -> String {
    let body = std::fs::read(root.join(format!("bvh/bandai/{name}.bvh"))).unwrap();
    let r = srv
        .client
        .post(format!(
            "{}/v1/takes?name={name}&library={library}&codec=quant",
            srv.base
        ))
        .bearer_auth(token)
        .body(body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string()
}

/// `GET path` with `token`: the status and the JSON answer.
async fn get_as(srv: &common::Server, token: &str, path: &str) -> (u16, Value) {
    let r = srv
        .client
        .get(format!("{}{path}", srv.base))
        .bearer_auth(token)
        .send()
        .await
        .unwrap();
    (r.status().as_u16(), r.json::<Value>().await.unwrap())
}

/// Approximate search (`index=approximate`): the first asks start the graph's build and are
/// refused as busy until it is in; then the graph proposes and the proposed takes are scored
/// exactly, so on a small archive the answer is exact search's, score for score. A token of
/// one library is never answered another's take (a copy of the query in it, nearer than any);
/// a take stored after the graph was built is found all the same (scored beside the graph's
/// proposals), and once deleted never again. A bad `index=` is a 400.
#[tokio::test(flavor = "multi_thread")]
async fn approximate_search_answers_what_exact_search_does() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let reader = common::token(&t.store, "reader", "read", Some(&["lab"])).await;
    let writer = common::token(&t.store, "writer", "admin", None).await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let put = |name: &'static str, library: &'static str| {
        let (srv, writer, root) = (&srv, writer.clone(), root.clone());
        async move { put_bandai(srv, &writer, &root, name, library).await }
    };
    let query = put(FILES[0], "lab").await;
    for name in &FILES[1..] {
        put(name, "lab").await;
    }
    put(FILES[0], "secret").await;
    let ask = |path: String| {
        let (srv, reader) = (&srv, reader.clone());
        async move { get_as(srv, &reader, &path).await }
    };
    let similar = format!("/v1/takes/{query}/similar?k=10&t0=1&t1=3");
    let (status, bad) = ask(format!("{similar}&index=nearest")).await;
    assert_eq!(status, 400, "{bad}");
    let approximate = || {
        let ask = &ask;
        let similar = similar.clone();
        async move {
            for _ in 0..600 {
                let (status, v) = ask(format!("{similar}&index=approximate")).await;
                if status == 200 {
                    return v;
                }
                assert_eq!(status, 503, "{v}");
                tokio::time::sleep(std::time::Duration::from_millis(50)).await;
            }
            panic!("the graph was never built");
        }
    };
    let a = approximate().await;
    let (status, exact) = ask(format!("{similar}&index=exact")).await;
    assert_eq!(status, 200);
    assert_eq!(a["searched"]["index"], "approximate", "{a}");
    assert_eq!(exact["searched"]["index"], "exact");
    assert_eq!(exact["searched"]["scored"], 9);
    assert_eq!(a["searched"]["takes"], 9, "{a}");
    assert_eq!(a["results"], exact["results"], "{a}\n{exact}");
    assert!(a["results"]
        .as_array()
        .unwrap()
        .iter()
        .all(|r| r["library"] == "lab"));
    // Small archives are exact by default.
    let (_, auto) = ask(similar.clone()).await;
    assert_eq!(auto["searched"]["index"], "exact");
    // A clip of fewer roles (the walk's pelvis, head and ankles alone, as TRC markers) is
    // compared on the roles it shares with each take: always exactly.
    let (_, record) = ask(format!("/v1/takes/{query}")).await;
    let roles = &record["body"]["roles"];
    let points: Vec<&str> = ["pelvis", "head", "left_ankle", "right_ankle"]
        .iter()
        .filter_map(|r| roles[*r][0].as_str())
        .collect();
    assert_eq!(points.len(), 4, "{roles}");
    let r = srv
        .client
        .get(format!(
            "{}/v1/takes/{query}/frames?format=trc&points={}",
            srv.base,
            points.join(",")
        ))
        .bearer_auth(&reader)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let trc = r.bytes().await.unwrap();
    let r = srv
        .client
        .post(format!(
            "{}/v1/search?index=approximate&t0=1&t1=3&k=3",
            srv.base
        ))
        .bearer_auth(&reader)
        .body(trc)
        .send()
        .await
        .unwrap();
    let status = r.status();
    let partial: Value = r.json().await.unwrap();
    assert_eq!(status, 200, "{partial}");
    assert_eq!(partial["searched"]["index"], "exact", "{partial}");
    assert!(
        !partial["query"]["missing_roles"]
            .as_array()
            .unwrap()
            .is_empty(),
        "{partial}"
    );

    // A copy stored after the graph was built: found first, as exact search finds it.
    let late = put(FILES[0], "lab").await;
    let (_, after) = ask(format!("{similar}&index=approximate")).await;
    assert_eq!(after["results"][0]["take"], late.as_str(), "{after}");
    assert_eq!(after["results"][0]["score"], 0.0, "{after}");
    assert_eq!(after["searched"]["takes"], 10, "{after}");
    let r = srv
        .client
        .delete(format!("{}/v1/takes/{late}", srv.base))
        .bearer_auth(&writer)
        .send()
        .await
        .unwrap();
    assert!(r.status().is_success(), "{}", r.status());
    let (_, gone) = ask(format!("{similar}&index=approximate")).await;
    assert_eq!(gone["results"], exact["results"], "{gone}");
    srv.stop().await;
    t.finish().await;
}

/// A token of library "lab" only: its results and counts are the same whatever other
/// libraries hold, a query take of another library is not found, and a clip search sees
/// its libraries alone.
#[tokio::test(flavor = "multi_thread")]
async fn a_library_token_searches_its_libraries_alone() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let reader = common::token(&t.store, "reader", "read", Some(&["lab"])).await;
    let writer = common::token(&t.store, "writer", "write", None).await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let file = |name: &str| std::fs::read(root.join(format!("bvh/bandai/{name}.bvh"))).unwrap();
    let put = |name: &'static str, library: &'static str| {
        let (srv, writer, root) = (&srv, writer.clone(), root.clone());
        async move { put_bandai(srv, &writer, &root, name, library).await }
    };
    let query = put(FILES[0], "lab").await;
    for name in &FILES[1..5] {
        put(name, "lab").await;
    }
    let ask = |path: String| {
        let (srv, reader) = (&srv, reader.clone());
        async move { get_as(srv, &reader, &path).await }
    };
    let similar = format!("/v1/takes/{query}/similar?k=10");
    let (status, before) = ask(similar.clone()).await;
    assert_eq!(status, 200, "{before}");
    assert_eq!(before["searched"]["takes"], 5);
    // The same walk in a library the token does not reach: nearer than any, never seen.
    let hidden = put(FILES[0], "secret").await;
    for name in &FILES[5..] {
        put(name, "secret").await;
    }
    let (_, after) = ask(similar.clone()).await;
    assert_eq!(after, before);
    let (_, elsewhere) = ask(format!("{similar}&library=secret")).await;
    assert_eq!(elsewhere["searched"]["takes"], 0, "{elsewhere}");
    assert_eq!(elsewhere["results"].as_array().unwrap().len(), 0);
    let (status, _) = ask(format!("/v1/takes/{hidden}/similar")).await;
    assert_eq!(status, 404);
    let r = srv
        .client
        .post(format!("{}/v1/search?take={hidden}", srv.base))
        .bearer_auth(&reader)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
    let r = srv
        .client
        .post(format!("{}/v1/search?k=100", srv.base))
        .bearer_auth(&reader)
        .body(file(FILES[0]))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let clip: Value = r.json().await.unwrap();
    assert_eq!(clip["searched"]["takes"], 5, "{clip}");
    assert!(clip["results"]
        .as_array()
        .unwrap()
        .iter()
        .all(|r| r["library"] == "lab"));
    srv.stop().await;
    t.finish().await;
}

/// Features are taken at ingest (one row a take), go with a deleted take, are stale once a
/// take's body is corrected (counted as unindexed, not compared) until the index job takes
/// them again, and are taken by the job for takes that have none (as stored before them).
#[tokio::test(flavor = "multi_thread")]
async fn features_are_kept_current_by_ingest_and_the_index_job() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 64 << 20).await;
        let file = |name: &str| std::fs::read(root.join(format!("bvh/bandai/{name}.bvh"))).unwrap();
        let mut ids = Vec::new();
        for name in &FILES[..4] {
            ids.push(
                ingest(
                    &srv,
                    &format!("name={name}&library=lab&codec=quant"),
                    file(name),
                )
                .await,
            );
        }
        let rows = || {
            count(
                &t.store,
                "SELECT COUNT(*) FROM take_features WHERE failed IS NULL",
            )
        };
        assert_eq!(rows().await, 4);
        assert_eq!(srv.delete(&format!("/v1/takes/{}", ids[3])).await, 204);
        assert_eq!(rows().await, 3);

        // A corrected body: stale until the job takes the take again.
        let r = srv
            .client
            .patch(format!("{}/v1/takes/{}", srv.base, ids[1]))
            .json(&serde_json::json!({"body": {"up": "y", "forward": "-z"}}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "{}", r.text().await.unwrap());
        let similar = format!("/v1/takes/{}/similar", ids[0]);
        let (_, a) = srv.get_json(&similar).await;
        let stale = a["searched"]["unindexed"].as_u64().unwrap();
        assert!(stale <= 1, "{a}");
        // Takes as stored before features were: the job takes them.
        execute(&t.store, "DELETE FROM take_features").await;
        let (_, b) = srv.get_json(&format!("/v1/takes/{}/similar", ids[2])).await;
        // The query take's are taken at once; the others wait for the job.
        assert_eq!(
            b["searched"]["takes"].as_u64().unwrap() + b["searched"]["unindexed"].as_u64().unwrap(),
            3,
            "{b}"
        );
        common::eventually(1200, || {
            let srv = &srv;
            let similar = similar.clone();
            async move {
                let (_, v) = srv.get_json(&similar).await;
                v["searched"]["takes"] == 3 && v["searched"]["unindexed"] == 0
            }
        })
        .await;
        assert_eq!(rows().await, 3);
        // The job says what it did.
        common::eventually(600, || {
            let srv = &srv;
            async move {
                let (_, jobs) = srv.get_json("/v1/jobs").await;
                jobs["items"].as_array().unwrap().iter().any(|j| {
                    j["kind"] == "index-motion"
                        && j["state"] == "succeeded"
                        && j["result"]["indexed"].as_u64() >= Some(1)
                })
            }
        })
        .await;
        srv.stop().await;
        t.finish().await;
    }
}
