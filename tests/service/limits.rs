//! The limits (`src/limits.rs`) as a hostile or careless client meets them: each of these
//! requests once crashed the server or let one client exhaust it. Every answer is a 4xx (or
//! a 503 with `Retry-After` at a capacity limit) in the one error shape, the server stays up,
//! and what it holds stays bounded — checked by the bytes it says it holds, not by time.

use crate::common;

use std::time::Duration;

use mocapstore::http::Config;
use mocapstore::limits::Limits;
use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use serde_json::{json, Value};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

use common::{eventually, gauge, raw};

fn is_error_shape(v: &Value) -> bool {
    v["error"]["code"].is_string() && v["error"]["message"].is_string()
}

async fn healthy(srv: &common::Server) {
    let (status, _, body) = srv.get("/healthz").await;
    assert_eq!(
        (status, body.as_slice()),
        (200, &b"ok"[..]),
        "the server is up"
    );
}

#[tokio::test]
async fn a_stream_of_twenty_billion_points_is_refused_before_anything_is_made() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    // Point names were built before the count was checked: this one aborted the process.
    for points in [json!(20_817_173_594u64), json!(2_000_000), json!(9_052)] {
        let (status, _, body) = srv
            .post_json("/v1/streams", &json!({"fps": 120, "points": points}))
            .await;
        assert_eq!(status, 400, "{points}: {body}");
        assert!(is_error_shape(&body), "{body}");
    }
    // 9,052 points stored a 983 MB basis: nothing is stored now.
    let (_, bases) = srv.get_json("/v1/bases").await;
    assert_eq!(bases["items"], json!([]));
    assert_eq!(t.store.count().await.unwrap(), 0);
    healthy(&srv).await;
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn a_deeply_nested_bvh_is_refused_not_a_stack_overflow() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    // 6,000 levels (540 KB) overflowed the parser's stack and aborted the process.
    let (status, body) = srv
        .post(
            "name=deep",
            mocapstore::motion::synthetic::chain_bvh(6_000).into_bytes(),
        )
        .await;
    assert_eq!(status, 422, "{body}");
    assert!(
        body["error"]["message"]
            .as_str()
            .unwrap()
            .contains("hierarchy depth"),
        "{body}"
    );
    healthy(&srv).await;
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn a_content_length_over_the_limit_is_refused_before_the_body_is_read() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    // 600 MiB declared, not one byte sent: the answer comes from the header alone.
    let head = format!(
        "POST /v1/takes?name=big HTTP/1.1\r\nHost: localhost\r\nContent-Length: {}\r\n\r\n",
        600u64 << 20
    );
    let (status, text, _conn) = raw(&srv.base, &head, b"").await;
    assert_eq!(status, 413, "{text}");
    assert!(text.contains("\"too_large\""), "{text}");
    assert_eq!(gauge(&srv, "mocapstore_request_body_bytes_held").await, 0);
    healthy(&srv).await;
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn uploads_past_the_server_budget_get_503_and_what_is_held_stays_bounded() {
    let t = common::sqlite().await;
    let budget = 4u64 << 20;
    let srv = common::start_with(
        t.store.clone(),
        Config {
            limits: Limits {
                upload_bytes: 3 << 20,
                inflight_bytes: budget,
                ..Limits::default()
            },
            ..Config::default()
        },
    )
    .await;
    let addr = srv.base.trim_start_matches("http://").to_string();
    // Two slow clients each declare 2 MiB and send 1.5 MiB: the budget counts what has
    // arrived (room for it, growing to the declared size), and together they hold it all.
    let mut slow = Vec::new();
    for _ in 0..2 {
        let mut s = TcpStream::connect(&addr).await.unwrap();
        let head = format!(
            "POST /v1/takes?name=slow HTTP/1.1\r\nHost: localhost\r\nContent-Length: {}\r\n\r\n",
            2u64 << 20
        );
        s.write_all(head.as_bytes()).await.unwrap();
        s.write_all(&vec![b' '; 1536 << 10]).await.unwrap();
        slow.push(s);
    }
    eventually(100, || async {
        gauge(&srv, "mocapstore_request_body_bytes_held").await == budget
    })
    .await;
    // A third upload, declared or chunked, is refused at once with Retry-After.
    let take = formats::write(&walker(60, 4, 60.0, 1, 0.0), Format::Json).unwrap();
    let head = format!(
        "POST /v1/takes?name=third HTTP/1.1\r\nHost: localhost\r\nContent-Length: {}\r\n\r\n",
        take.len()
    );
    let (status, text, _c) = raw(&srv.base, &head, &take).await;
    assert_eq!(status, 503, "{text}");
    assert!(
        text.to_ascii_lowercase().contains("retry-after: 2"),
        "{text}"
    );
    assert!(text.contains("\"busy\""), "{text}");
    let mut chunked = Vec::new();
    chunked.extend_from_slice(format!("{:x}\r\n", take.len()).as_bytes());
    chunked.extend_from_slice(&take);
    chunked.extend_from_slice(b"\r\n0\r\n\r\n");
    let (status, text, _c) = raw(
        &srv.base,
        "POST /v1/takes?name=chunked HTTP/1.1\r\nHost: localhost\r\nTransfer-Encoding: chunked\r\n\r\n",
        &chunked,
    )
    .await;
    assert_eq!(status, 503, "{text}");
    assert!(gauge(&srv, "mocapstore_request_body_bytes_held").await <= budget);
    // The slow clients give up: their reservations come back, and uploads go through.
    drop(slow);
    eventually(100, || async {
        gauge(&srv, "mocapstore_request_body_bytes_held").await == 0
    })
    .await;
    let (status, body) = srv.post("name=after", take).await;
    assert_eq!(status, 201, "{body}");
    eventually(100, || async {
        gauge(&srv, "mocapstore_request_body_bytes_held").await == 0
    })
    .await;
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn open_streams_are_bounded_per_server() {
    let t = common::sqlite().await;
    let srv = common::start_with(
        t.store.clone(),
        Config {
            limits: Limits {
                open_streams: 2,
                ..Limits::default()
            },
            ..Config::default()
        },
    )
    .await;
    let small = json!({"fps": 60, "points": 3});
    let open = || srv.post_json("/v1/streams", &small);
    let (a, _, first) = open().await;
    let (b, _, _) = open().await;
    assert_eq!((a, b), (201, 201));
    let r = srv
        .client
        .post(format!("{}/v1/streams", srv.base))
        .json(&json!({"fps": 60, "points": 3}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 503);
    assert_eq!(r.headers()["retry-after"], "2");
    assert!(is_error_shape(&r.json().await.unwrap()));
    assert_eq!(gauge(&srv, "mocapstore_streams_open").await, 2);
    // Finishing one frees its place.
    let id = first["id"].as_str().unwrap();
    let (status, _, _) = srv
        .post_json(&format!("/v1/streams/{id}/finish"), &json!({}))
        .await;
    assert_eq!(status, 200);
    let (c, _, _) = open().await;
    assert_eq!(c, 201);
    // A chunk of more samples than a stream may keep pending is refused at open.
    let (status, _, body) = srv
        .post_json(
            "/v1/streams",
            &json!({"fps": 100000, "points": 1000, "chunk_seconds": 60}),
        )
        .await;
    assert_eq!(status, 400, "{body}");
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn a_live_take_header_is_not_rewritten_by_appends() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        let (status, _, info) = srv
            .post_json(
                "/v1/streams",
                &json!({"fps": 60, "points": 4, "chunk_seconds": 0.1}),
            )
            .await;
        assert_eq!(status, 201, "{info}");
        let id = info["id"].as_str().unwrap().to_string();
        let header_at_open = t.store.get(&id).await.unwrap().unwrap().header;
        let m = walker(120, 4, 60.0, 2, 0.0);
        for batch in m.positions().chunks(12 * 20) {
            let (status, _, r) = srv
                .post_json(
                    &format!("/v1/streams/{id}/frames"),
                    &json!({"frames": batch.chunks(12).collect::<Vec<_>>()}),
                )
                .await;
            assert_eq!(status, 200, "{r}");
            // Each commit adds a chunk row and running totals; the header stays as opened,
            // so an append costs the same however long the stream has run.
            let row = t.store.get(&id).await.unwrap().unwrap();
            assert_eq!(row.header, header_at_open, "{}", t.name);
            assert!(row.live_until.is_some());
        }
        assert_eq!(t.store.chunk_count().await.unwrap(), 20, "{}", t.name);
        // While live, ranges are served from the chunk rows' index.
        let (status, _, body) = srv
            .get(&format!(
                "/v1/takes/{id}/frames?start=10&end=100&format=f32"
            ))
            .await;
        assert_eq!((status, body.len()), (200, 90 * 12 * 4), "{}", t.name);
        // A take being recorded is not deleted from under its stream.
        assert_eq!(srv.delete(&format!("/v1/takes/{id}")).await, 409);
        let (status, _, done) = srv
            .post_json(&format!("/v1/streams/{id}/finish"), &json!({}))
            .await;
        assert_eq!(status, 200, "{done}");
        assert_eq!(done["live"], false);
        let row = t.store.get(&id).await.unwrap().unwrap();
        assert!(row.live_until.is_none());
        assert_ne!(
            row.header, header_at_open,
            "the index is written once, at the end"
        );
        let (status, _, again) = srv
            .get(&format!(
                "/v1/takes/{id}/frames?start=10&end=100&format=f32"
            ))
            .await;
        assert_eq!((status, &again), (200, &body), "{}", t.name);
        srv.stop().await;
        t.finish().await;
    }
}

#[tokio::test]
async fn a_stream_whose_server_died_is_closed_and_says_so_everywhere() {
    for mut t in common::all().await {
        // A server that stops without finishing its stream (as after kill -9: nothing runs
        // at exit), and a lease that has already run out when the next server starts.
        let config = Config {
            stream_lease: Duration::ZERO,
            ..Config::default()
        };
        let a = common::start_with(t.store.clone(), config.clone()).await;
        let (_, _, info) = a
            .post_json(
                "/v1/streams",
                &json!({"fps": 60, "points": 3, "chunk_seconds": 0.5}),
            )
            .await;
        let id = info["id"].as_str().unwrap().to_string();
        let frames = walker(75, 3, 60.0, 4, 0.0);
        let (status, _, r) = a
            .post_json(
                &format!("/v1/streams/{id}/frames"),
                &json!({"frames": frames.positions().chunks(9).collect::<Vec<_>>()}),
            )
            .await;
        assert_eq!(
            (status, r["frames_committed"].as_u64()),
            (200, Some(60)),
            "{r}"
        );
        a.stop().await;
        t.reopen().await;

        let b = common::start_with(t.store.clone(), config).await;
        let (status, row) = b.get_json(&format!("/v1/takes/{id}")).await;
        assert_eq!(status, 200);
        assert_eq!(row["live"], false, "{}: {row}", t.name);
        assert!(row["meta"]["interrupted"].is_string(), "{row}");
        assert_eq!(row["frames"], 60);
        let (status, s) = b.get_json(&format!("/v1/streams/{id}")).await;
        assert_eq!(status, 409, "{s}");
        assert!(
            s["error"]["message"].as_str().unwrap().contains("finished"),
            "{s}"
        );
        let (status, _, body) = b.get(&format!("/v1/takes/{id}/frames?format=f32")).await;
        assert_eq!((status, body.len()), (200, 60 * 9 * 4));
        b.stop().await;
        t.finish().await;
    }
}

#[tokio::test]
async fn data_that_contradicts_its_header_is_refused_unless_lenient() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let mut text = String::from(
        "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition \
         Zrotation Xrotation Yrotation\nJOINT Leg\n{\nOFFSET 10 -40 0\nCHANNELS 3 Zrotation \
         Xrotation Yrotation\nEnd Site\n{\nOFFSET 0 -40 0\n}\n}\n}\nMOTION\nFrames: 40\n\
         Frame Time: 0.0333333\n",
    );
    for f in 0..40 {
        text.push_str(&format!("{f} 90 0 {} 0 0 {} 0 0\n", f % 7, f % 5));
    }
    // Cut at a line boundary: 25 of the 40 declared frames.
    let lines: Vec<&str> = text.lines().collect();
    let motion_at = lines.iter().position(|l| *l == "MOTION").unwrap();
    let cut = lines[..motion_at + 3 + 25].join("\n") + "\n";
    // A channel value of 1e308.
    let mut huge: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    let row = &mut huge[motion_at + 3 + 5];
    let first = row.split(' ').next().unwrap().to_string();
    *row = row.replacen(&first, "1e308", 1);
    let huge = huge.join("\n") + "\n";
    for (what, body) in [("cut short", cut), ("1e308", huge)] {
        let (status, r) = srv.post("name=strict", body.clone().into_bytes()).await;
        assert_eq!(status, 422, "{what}: {r}");
        assert!(
            r["error"]["message"].as_str().unwrap().contains("lenient"),
            "{r}"
        );
        let (status, r) = srv
            .post("name=lenient&lenient=true", body.into_bytes())
            .await;
        assert_eq!(status, 201, "{what}: {r}");
        assert!(
            r["warnings"]
                .as_array()
                .unwrap()
                .iter()
                .any(|w| w.as_str().unwrap().contains("lenient")),
            "{what}: {r}"
        );
    }
    // A unit beyond any physical scale once reached the codecs, which decoded NaN (500).
    let take = formats::write(&walker(60, 4, 60.0, 1, 0.0), Format::Json).unwrap();
    let (status, r) = srv.post("unit=1e308", take.clone()).await;
    assert_eq!(status, 400, "{r}");
    // So once did a bound of 1e308 mm (a stream's step was not a number: 500).
    let (status, r) = srv.post("max_error_mm=1e308", take).await;
    assert_eq!(status, 400, "{r}");
    let (status, _, r) = srv
        .post_json(
            "/v1/streams",
            &json!({"fps": 60, "points": 2, "mean_error_mm": 1.6e308}),
        )
        .await;
    assert_eq!(status, 400, "{r}");
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn every_error_is_in_the_one_shape_and_the_contract_drift_is_closed() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let take = formats::write(&walker(60, 4, 60.0, 1, 0.0), Format::Json).unwrap();
    let (_, r) = srv.post("name=x", take).await;
    let id = r["id"].as_str().unwrap().to_string();
    // Unknown routes and methods.
    let (status, v) = srv.get_json("/v2/nothing").await;
    assert_eq!(status, 404);
    assert!(is_error_shape(&v), "{v}");
    let r = srv
        .client
        .put(format!("{}/v1/takes", srv.base))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 405);
    assert!(is_error_shape(&r.json().await.unwrap()));
    // Queries and bodies that once answered 200 or an undocumented status.
    let (status, v) = srv.get_json("/v1/bases?kind=AAA").await;
    assert_eq!(status, 400, "{v}");
    let r = srv
        .client
        .patch(format!("{}/v1/takes/{id}", srv.base))
        .json(&json!({"name": null}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 400);
    for ids in [json!(["nope"]), json!([])] {
        let (status, _, v) = srv.post_json("/v1/bases", &json!({"ids": ids})).await;
        assert_eq!(status, 400, "{ids}: {v}");
        assert!(is_error_shape(&v));
    }
    let (status, v) = srv
        .get_json(&format!("/v1/takes/{id}/frames?start=0&t1=1"))
        .await;
    assert_eq!(status, 400, "{v}");
    let (status, _, v) = srv
        .post_json("/v1/streams", &json!({"fps": 1e6, "points": 3}))
        .await;
    assert_eq!(status, 400, "{v}");
    healthy(&srv).await;
    srv.stop().await;
    t.finish().await;
}

#[tokio::test]
async fn an_append_larger_than_its_limit_is_refused_before_it_is_read() {
    let t = common::sqlite().await;
    let srv = common::start_with(
        t.store.clone(),
        Config {
            limits: Limits {
                append_bytes: 1024,
                ..Limits::default()
            },
            ..Config::default()
        },
    )
    .await;
    let (_, _, s) = srv
        .post_json("/v1/streams", &json!({"fps": 60, "points": 2}))
        .await;
    let id = s["id"].as_str().unwrap().to_string();
    // Frames per append are bounded by the append body limit (24 bytes a frame here).
    let head = format!(
        "POST /v1/streams/{id}/frames HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/octet-stream\r\nContent-Length: {}\r\n\r\n",
        100 * 24
    );
    let (status, text, _c) = raw(&srv.base, &head, b"").await;
    assert_eq!(status, 413, "{text}");
    let r = srv
        .client
        .post(format!("{}/v1/streams/{id}/frames", srv.base))
        .header("content-type", "application/octet-stream")
        .body(vec![0u8; 40 * 24])
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 200);
    srv.stop().await;
    t.finish().await;
}
