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
            "/v1/sequences/{id}/frames?start={start}&end={end}&format=f32"
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
        let (_, row) = srv.get_json(&format!("/v1/sequences/{id}")).await;
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
        assert_eq!(
            append(&srv, &id3, &all[..w], false).await.0,
            409,
            "not open on this server"
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
