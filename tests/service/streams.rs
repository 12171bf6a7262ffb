//! Live streams over HTTP, on every backend: frames coded and committed chunk by chunk and
//! fetchable while the take is still being recorded; finishing, re-encoding, abandoning.

use crate::common;

use mocapstore::motion::metrics;
use mocapstore::motion::synthetic::walker;
use serde_json::{json, Value};

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

async fn append(srv: &common::Server, id: &str, frames: &[f32], flush: bool) -> (u16, Value) {
    let r = srv
        .client
        .post(format!("{}/v1/streams/{id}/frames?flush={flush}", srv.base))
        .header("content-type", "application/octet-stream")
        .body(f32_bytes(frames))
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap_or(Value::Null))
}

async fn fetch(srv: &common::Server, id: &str, start: usize, end: usize) -> Vec<f32> {
    let (status, _, body) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?start={start}&end={end}&format=f32"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    body.chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

fn within(original: &[f32], served: &[f32], points: usize, bound: f64) {
    assert_eq!(original.len(), served.len());
    for (a, b) in original.iter().zip(served) {
        assert_eq!(a.is_nan(), b.is_nan(), "gaps stay gaps");
    }
    let s = metrics::compare(original, served, points, 1.0).unwrap();
    assert!(s.max_mm <= bound, "max {} over {bound}", s.max_mm);
}

#[tokio::test]
async fn streams_commit_chunk_by_chunk_and_ranges_are_fetchable_while_live() {
    for mut t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        let (points, w) = (6, 18);
        let m = walker(700, points, 120.0, 5, 0.05);
        let all = m.positions();

        let (status, loc, info) = srv
            .post_json(
                "/v1/streams",
                &json!({"name": "live", "fps": 120.0, "points": points, "unit": "mm",
                        "max_error_mm": 1.0, "chunk_seconds": 0.5}),
            )
            .await;
        assert_eq!(status, 201, "{info}");
        let id = info["id"].as_str().unwrap().to_string();
        assert_eq!(loc.unwrap(), format!("/v1/streams/{id}"));
        assert_eq!(
            (info["codec"].as_str(), info["chunk_frames"].as_u64()),
            (Some("lsdt-frame"), Some(60))
        );

        // Batches of 37 frames: whole chunks of 60 are committed as they fill.
        let mut sent = 0;
        while sent + 37 <= 400 {
            let (status, info) = append(&srv, &id, &all[sent * w..(sent + 37) * w], false).await;
            assert_eq!(status, 200, "{info}");
            sent += 37;
            assert_eq!(info["frames_received"].as_u64().unwrap() as usize, sent);
            assert_eq!(
                info["frames_committed"].as_u64().unwrap() as usize,
                sent / 60 * 60
            );
        }
        // What is committed is fetchable now, within the bound, from any start.
        let committed = sent / 60 * 60;
        let served = fetch(&srv, &id, 0, committed).await;
        within(&all[..committed * w], &served, points, 1.0);
        let served = fetch(&srv, &id, 97, committed).await;
        within(&all[97 * w..committed * w], &served, points, 1.0);
        let (_, row) = srv.get_json(&format!("/v1/takes/{id}")).await;
        assert_eq!(row["frames"].as_u64().unwrap() as usize, committed);
        assert_eq!(row["live"], true);

        // Flush: everything received is committed.
        let (status, info) = append(&srv, &id, &all[sent * w..450 * w], true).await;
        assert_eq!(status, 200, "{info}");
        assert_eq!(info["frames_committed"].as_u64(), Some(450));
        sent = 450;
        // JSON frames, null for a missing coordinate.
        let mut frames: Vec<Value> = Vec::new();
        for f in sent..sent + 2 {
            let mut v: Vec<Value> = all[f * w..(f + 1) * w]
                .iter()
                .map(|x| if x.is_nan() { Value::Null } else { json!(x) })
                .collect();
            v[0] = Value::Null;
            frames.push(Value::Array(v));
        }
        let (status, _, info) = srv
            .post_json(
                &format!("/v1/streams/{id}/frames"),
                &json!({ "frames": frames }),
            )
            .await;
        assert_eq!(status, 200, "{info}");
        // Bad input: not whole frames, unknown stream.
        let (status, body) = append(&srv, &id, &all[..5], false).await;
        assert_eq!(status, 400, "{body}");
        assert_eq!(append(&srv, "nope", &all[..w], false).await.0, 404);

        // Finish: the rest is committed; the take is whole and no longer live.
        let (status, _, row) = srv
            .post_json(&format!("/v1/streams/{id}/finish"), &json!({}))
            .await;
        assert_eq!(status, 200, "{row}");
        assert_eq!(row["frames"].as_u64(), Some(452));
        assert_eq!(row["live"], false);
        assert!(row["max_mm"].as_f64().unwrap() <= 1.0);
        let served = fetch(&srv, &id, 0, 452).await;
        let mut want = all[..452 * w].to_vec();
        want[450 * w..450 * w + 3].fill(f32::NAN);
        want[451 * w..451 * w + 3].fill(f32::NAN);
        within(&want, &served, points, 1.0);
        assert_eq!(append(&srv, &id, &all[..w], false).await.0, 409);

        // lsdt-clip, re-encoded on finish from the frames as sent.
        let (status, _, info) = srv
            .post_json(
                "/v1/streams",
                &json!({"fps": 120.0, "points": points, "codec": "lsdt-clip",
                        "mean_error_mm": 2.0, "reencode_on_finish": true}),
            )
            .await;
        assert_eq!(status, 201, "{info}");
        let id2 = info["id"].as_str().unwrap().to_string();
        for c in all.chunks(100 * w) {
            assert_eq!(append(&srv, &id2, c, false).await.0, 200);
        }
        let (status, _, row) = srv
            .post_json(&format!("/v1/streams/{id2}/finish"), &json!({}))
            .await;
        assert_eq!(status, 200, "{row}");
        assert_eq!(row["frames"].as_u64(), Some(700));
        let served = fetch(&srv, &id2, 0, 700).await;
        let s = metrics::compare(all, &served, points, 1.0).unwrap();
        assert!(s.mean_mm <= 2.0, "mean {}", s.mean_mm);

        // Abandoned: the client goes away mid-chunk; what was committed survives the server.
        let (_, _, info) = srv
            .post_json("/v1/streams", &json!({"fps": 120.0, "points": points}))
            .await;
        let id3 = info["id"].as_str().unwrap().to_string();
        append(&srv, &id3, &all[..150 * w], false).await;
        srv.stop().await;
        t.reopen().await;
        let srv = common::start(t.store.clone(), 8 << 20).await;
        let served = fetch(&srv, &id3, 0, 120).await;
        within(&all[..120 * w], &served, points, 1.0);
        // Its server is gone and its lease (a minute) runs: a 503 to retry, until the
        // next request after the lease takes the stream over (tests/service/cluster.rs).
        let (status, e) = append(&srv, &id3, &all[..w], false).await;
        assert_eq!(status, 503, "{e}");
        assert!(
            e["error"]["message"]
                .as_str()
                .unwrap()
                .contains("does not answer"),
            "{e}"
        );
        srv.stop().await;
        t.finish().await;
    }
}

/// The frames a stream sends in [`stored_stream_bytes`]: 2.5 s of 7 points at 100 fps with
/// gaps, in uneven appends, one of them flushed mid-chunk.
fn stream_script() -> (mocapstore::motion::Motion, Vec<(usize, usize, bool)>) {
    let m = walker(250, 7, 100.0, 23, 0.04);
    let appends = vec![
        (0, 37, false),
        (37, 130, false),
        (130, 141, true),
        (141, 250, false),
    ];
    (m, appends)
}

/// BLAKE3 (hex) of a stored take's closed header and its chunk payloads, in order.
async fn stored_container_digest(store: &mocapstore::store::Store, id: &str) -> String {
    let row = store.get(id).await.unwrap().unwrap();
    let mut h = blake3::Hasher::new();
    h.update(&row.header);
    let chunks = store.chunks(id, 0, i64::MAX).await.unwrap();
    assert!(!chunks.is_empty());
    for c in &chunks {
        h.update(&c.payload);
    }
    h.finalize().to_hex().to_string()
}

/// What the service stores for a scripted stream, per codec: the container the stream
/// encoder of the codec layer must go on producing byte for byte (these digests were taken
/// from the service before streams were moved onto that interface).
async fn stored_stream_bytes(
    srv: &common::Server,
    store: &mocapstore::store::Store,
    codec: &str,
) -> String {
    let (m, appends) = stream_script();
    let w = m.point_count() * 3;
    let all = m.positions();
    let (status, _, info) = srv
        .post_json(
            "/v1/streams",
            &json!({"fps": 100.0, "points": m.point_count(), "unit": "mm", "codec": codec,
                    "max_error_mm": 0.5, "chunk_seconds": 0.4}),
        )
        .await;
    assert_eq!(status, 201, "{info}");
    let id = info["id"].as_str().unwrap().to_string();
    for (a, b, flush) in appends {
        let (status, info) = append(srv, &id, &all[a * w..b * w], flush).await;
        assert_eq!(status, 200, "{info}");
    }
    let (status, _, row) = srv
        .post_json(&format!("/v1/streams/{id}/finish"), &json!({}))
        .await;
    assert_eq!(status, 200, "{row}");
    stored_container_digest(store, &id).await
}

/// The same script through the codec layer's stream encoder alone, no service: BLAKE3 of
/// the closed header and the chunks it hands out.
fn encoder_stream_bytes(codec: &str) -> String {
    use mocapstore::codec::stream::{StreamEncoder, StreamSpec};
    let (m, appends) = stream_script();
    let w = m.point_count() * 3;
    let basis = std::sync::Arc::new(mocapstore::codec::lsdt::spatial::dct_basis(m.point_count()));
    let spec = StreamSpec {
        points: m.point_count(),
        fps: 100.0,
        metres_per_unit: 0.001,
        bound: mocapstore::codec::ErrorBound::max(0.5),
        chunk_frames: 40,
        shared: Some(&basis),
    };
    let mut e = StreamEncoder::open(codec.parse().unwrap(), &spec).unwrap();
    let mut payloads = Vec::new();
    let pushes = appends
        .iter()
        .map(|&(a, b, flush)| (&m.positions()[a * w..b * w], flush))
        .chain([(&[][..], true)]);
    for (frames, flush) in pushes {
        for chunk in e.push(frames, flush).unwrap() {
            payloads.push(chunk.payload.clone());
            e.confirm(chunk).unwrap();
        }
    }
    assert_eq!(e.committed().frames, m.frame_count());
    let mut h = blake3::Hasher::new();
    h.update(&e.closed_header().to_bytes());
    for p in &payloads {
        h.update(p);
    }
    h.finalize().to_hex().to_string()
}

#[tokio::test]
async fn streams_store_the_same_bytes_as_before_streams_moved_to_the_codec_layer() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        for (codec, want) in [
            (
                "lsdt-frame",
                "e702a8f2d1103063c6e06bb71b789dafa4677de426eef1b7c960ea75e25033d4",
            ),
            (
                "lsdt-clip",
                "1b3f57b448cac716398f00ab26a88866dc7d1802988ea631dd398a7d9734b3c1",
            ),
        ] {
            let got = stored_stream_bytes(&srv, &t.store, codec).await;
            assert_eq!(got, want, "{}: {codec}", t.name);
            assert_eq!(
                encoder_stream_bytes(codec),
                want,
                "{codec}: the codec layer alone"
            );
        }
        srv.stop().await;
        t.finish().await;
    }
}

/// Frames of a `frames` event.
fn event_frames(e: &Value) -> Vec<f32> {
    use base64::Engine;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(e["data"].as_str().unwrap())
        .unwrap();
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

async fn watch(srv: &common::Server, id: &str) -> reqwest::Response {
    srv.client
        .get(format!("{}/v1/streams/{id}/events", srv.base))
        .send()
        .await
        .unwrap()
}

/// What the viewer's live page reads: every append as it arrives, before it is coded, with
/// when it was received and captured; the newest frame for a watcher that joins late; the
/// end when the stream finishes. Watchers are bounded; a closed or unknown stream has none.
#[tokio::test]
async fn watchers_see_frames_as_they_arrive_and_the_end() {
    for t in common::all().await {
        // One caller may watch a stream as many times as the stream takes watchers here
        // (the share per caller has its own test, in `hostile`).
        let srv = common::start_with(
            t.store.clone(),
            mocapstore::http::Config {
                limits: mocapstore::limits::Limits {
                    watchers_per_caller: mocapstore::limits::STREAM_WATCHERS as u64,
                    ..Default::default()
                },
                ..Default::default()
            },
        )
        .await;
        let points = 3;
        let (status, _, info) = srv
            .post_json(
                "/v1/streams",
                &json!({"fps": 120.0, "points": points, "unit": "mm", "max_error_mm": 1.0}),
            )
            .await;
        assert_eq!(status, 201, "{info}");
        let id = info["id"].as_str().unwrap().to_string();

        let r = watch(&srv, &id).await;
        assert_eq!(r.status(), 200);
        assert_eq!(r.headers()["content-type"], "text/event-stream");
        let mut a = common::Events::new(r);
        let (name, hello) = a.next().await.unwrap();
        assert_eq!(name, "stream", "{hello}");
        assert_eq!(hello["id"], id.as_str());
        assert_eq!(hello["points"], points);
        let now = mocapstore::service::now_ms();
        assert!((hello["server_ms"].as_i64().unwrap() - now).abs() < 10_000);

        // An append reaches the watcher as sent, with its times.
        let m = walker(5, points, 120.0, 3, 0.0);
        let sent = m.positions().to_vec();
        let r = srv
            .client
            .post(format!(
                "{}/v1/streams/{id}/frames?captured_ms=1234",
                srv.base
            ))
            .header("content-type", "application/octet-stream")
            .body(f32_bytes(&sent))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        let (name, e) = a.next().await.unwrap();
        assert_eq!(name, "frames", "{e}");
        assert_eq!(
            (e["first"].as_u64(), e["frames"].as_u64()),
            (Some(0), Some(5))
        );
        assert_eq!(e["captured_ms"], 1234);
        let received = e["received_ms"].as_i64().unwrap();
        assert!((received - mocapstore::service::now_ms()).abs() < 10_000);
        assert_eq!(event_frames(&e), sent);

        // A watcher joining now sees the newest frame at once.
        let mut b = common::Events::new(watch(&srv, &id).await);
        assert_eq!(b.next().await.unwrap().0, "stream");
        let (name, e) = b.next().await.unwrap();
        assert_eq!(name, "frames");
        assert_eq!(
            (e["first"].as_u64(), e["frames"].as_u64()),
            (Some(4), Some(1))
        );
        assert_eq!(event_frames(&e), sent[4 * 9..].to_vec());

        // JSON frames with a gap: NaN on the wire; no capture time said, none shown.
        let r = srv
            .client
            .post(format!("{}/v1/streams/{id}/frames", srv.base))
            .json(&json!([[1.0, 2.0, 3.0, null, 5.0, 6.0, 7.0, 8.0, 9.0]]))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        for w in [&mut a, &mut b] {
            let (name, e) = w.next().await.unwrap();
            assert_eq!(name, "frames");
            assert_eq!(e["first"], 5);
            assert!(e["captured_ms"].is_null(), "{e}");
            let v = event_frames(&e);
            assert!(v[3].is_nan() && v[8] == 9.0, "{v:?}");
        }

        // A large append: watchers get its newest frames, at most 50,000 samples.
        let big = walker(20_000, points, 120.0, 4, 0.0);
        let (status, _) = append(&srv, &id, big.positions(), false).await;
        assert_eq!(status, 200);
        let (_, e) = a.next().await.unwrap();
        let kept = 50_000 / points;
        assert_eq!(e["frames"].as_u64(), Some(kept as u64));
        assert_eq!(e["first"].as_u64(), Some((6 + 20_000 - kept) as u64));
        assert_eq!(
            event_frames(&e),
            big.positions()[(20_000 - kept) * 9..].to_vec()
        );
        b.next().await.unwrap();

        // A capture time that is not one.
        for bad in ["-1", "40000000000000", "soon"] {
            let r = srv
                .client
                .post(format!(
                    "{}/v1/streams/{id}/frames?captured_ms={bad}",
                    srv.base
                ))
                .json(&json!([[1, 2, 3, 4, 5, 6, 7, 8, 9]]))
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 400, "captured_ms={bad}");
        }

        // At most 16 watchers; the 17th is told to come back.
        let mut more = Vec::new();
        for _ in 0..14 {
            let r = watch(&srv, &id).await;
            assert_eq!(r.status(), 200);
            more.push(r);
        }
        let r = watch(&srv, &id).await;
        assert_eq!(r.status(), 503);
        assert!(r.headers().contains_key("retry-after"));
        let body: Value = r.json().await.unwrap();
        assert!(
            body["error"]["message"]
                .as_str()
                .unwrap()
                .contains("16 watchers"),
            "{body}"
        );
        drop(more);

        // Finishing ends every watch.
        let (status, _, done) = srv
            .post_json(&format!("/v1/streams/{id}/finish"), &json!({}))
            .await;
        assert_eq!(status, 200, "{done}");
        for w in [&mut a, &mut b] {
            let (name, e) = w.next().await.unwrap();
            assert_eq!(
                (name.as_str(), e["reason"].as_str()),
                ("end", Some("finished"))
            );
            assert!(w.next().await.is_none(), "the response ends");
        }
        assert_eq!(watch(&srv, &id).await.status(), 409);
        assert_eq!(watch(&srv, "no-such-stream").await.status(), 404);
        srv.stop().await;
        t.finish().await;
    }
}

/// A server shutting down ends its watches rather than wait for them.
#[tokio::test]
async fn shutting_down_ends_watches() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let (_, _, info) = srv
        .post_json("/v1/streams", &json!({"fps": 60.0, "points": 2}))
        .await;
    let id = info["id"].as_str().unwrap();
    let mut w = common::Events::new(watch(&srv, id).await);
    assert_eq!(w.next().await.unwrap().0, "stream");
    tokio::time::timeout(std::time::Duration::from_secs(10), srv.stop())
        .await
        .expect("the server stops with a watch open");
    let (name, e) = w.next().await.unwrap();
    assert_eq!(name, "end");
    assert_eq!(e["reason"], "the server is shutting down");
    t.finish().await;
}

/// A watcher that does not read holds neither the producer nor unbounded memory: appends go
/// on, and when it reads again it is told how many it missed.
#[tokio::test]
async fn a_slow_watcher_skips_appends_and_never_holds_the_producer() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let points = 500;
    let (status, _, info) = srv
        .post_json(
            "/v1/streams",
            &json!({"fps": 100.0, "points": points, "unit": "mm", "max_error_mm": 5.0}),
        )
        .await;
    assert_eq!(status, 201, "{info}");
    let id = info["id"].as_str().unwrap().to_string();
    let mut w = common::Events::new(watch(&srv, &id).await);
    assert_eq!(w.next().await.unwrap().0, "stream");
    // 100 frames × 500 points an append: 800 KB of events each, 48 MB in all, far more than
    // the sockets buffer and the 16 appends queued.
    let m = walker(100, points, 100.0, 9, 0.0);
    for _ in 0..60 {
        let (status, v) = append(&srv, &id, m.positions(), false).await;
        assert_eq!(status, 200, "{v}");
    }
    let mut seen = 0;
    let mut skipped = 0;
    loop {
        let (name, e) = w.next().await.unwrap();
        match name.as_str() {
            "frames" => seen += 1,
            "skipped" => skipped += e["appends"].as_u64().unwrap(),
            other => panic!("{other}: {e}"),
        }
        if seen + skipped == 60 {
            break;
        }
    }
    assert!(skipped > 0, "{seen} seen, none skipped");
    srv.stop().await;
    t.finish().await;
}

/// An append numbered with `first` adds each frame once: a retry of an append the stream
/// has already (its answer lost) adds nothing, an overlapping one only its new frames, and
/// one that would leave a gap is refused, saying where to resume.
#[tokio::test]
async fn numbered_appends_add_each_frame_once() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let (status, _, s) = srv
        .post_json("/v1/streams", &json!({"name": "n", "fps": 60, "points": 2}))
        .await;
    assert_eq!(status, 201, "{s}");
    let id = s["id"].as_str().unwrap().to_string();
    let frames = |n: usize, from: usize| json!({"frames": (from..from + n).map(|f| vec![f as f64, 0.0, 0.0, 1.0, 1.0, 1.0]).collect::<Vec<_>>()});
    for (first, body, want) in [
        (0, frames(10, 0), 10),
        (0, frames(10, 0), 10),
        (5, frames(10, 5), 15),
    ] {
        let (status, _, r) = srv
            .post_json(&format!("/v1/streams/{id}/frames?first={first}"), &body)
            .await;
        assert_eq!(status, 200, "{r}");
        assert_eq!(r["frames_received"], want, "first={first}: {r}");
    }
    let (status, _, r) = srv
        .post_json(&format!("/v1/streams/{id}/frames?first=20"), &frames(3, 20))
        .await;
    assert_eq!(status, 409, "{r}");
    assert!(
        r["error"]["message"]
            .as_str()
            .unwrap()
            .contains("send from frame 15"),
        "{r}"
    );
    let (status, _, take) = srv
        .post_json(&format!("/v1/streams/{id}/finish"), &json!({}))
        .await;
    assert_eq!(status, 200, "{take}");
    // Frame 12 is the one sent as frame 12, once.
    let (_, _, body) = srv
        .get(&format!("/v1/takes/{id}/frames?start=12&end=13"))
        .await;
    // Within the 1 mm bound: a frame appended twice would be off by 5.
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert!(
        (v["frames"][0][0][0].as_f64().unwrap() - 12.0).abs() <= 1.0,
        "{v}"
    );
    srv.stop().await;
    t.finish().await;
}
