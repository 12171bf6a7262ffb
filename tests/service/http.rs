//! The real server on 127.0.0.1:0, over HTTP, on SQLite and (with MOCAP_TEST_PG_URL) Postgres.

use crate::common;

use crate::common::start;

use mocapstore::corpus;
use mocapstore::motion::formats::{self, Format, ReadOptions};
use mocapstore::motion::{metrics, Motion};
use serde_json::Value;

/// A corpus file (tests that use one first check, with `corpus::for_tests`, that there is a
/// corpus; none configured, they pass after one loud line).
fn corpus_bytes(rel: &str) -> Vec<u8> {
    std::fs::read(corpus::root().join(rel)).unwrap()
}

fn load(bytes: &[u8], opts: &ReadOptions) -> Motion {
    formats::read(bytes, opts).unwrap().motion
}

/// Error body shape: {"error": {"code", "message"}}.
fn assert_error(status: u16, body: &Value, want: u16) {
    assert_eq!(status, want, "{body}");
    assert!(
        body["error"]["code"].is_string() && body["error"]["message"].is_string(),
        "{body}"
    );
}

#[tokio::test]
async fn ingest_fetch_and_errors_on_every_backend() {
    if corpus::for_tests().is_none() {
        return;
    }
    for t in common::all().await {
        let store = t.store.clone();
        let srv = start(store.clone(), 8 << 20).await;
        let (status, _, body) = srv.get("/healthz").await;
        assert_eq!((status, body.as_slice()), (200, &b"ok"[..]));

        // One take of each input format; NPY and JSON written from a C3D take.
        let c3d = corpus_bytes("c3d/btkdata__others__Gait.c3d");
        let c3d_motion = load(&c3d, &ReadOptions::default());
        let npy = formats::write(&c3d_motion, Format::Npy).unwrap();
        let json = formats::write(&c3d_motion, Format::Json).unwrap();
        let uploads: Vec<(&str, Vec<u8>, String)> = vec![
            (
                "bvh",
                corpus_bytes("bvh/cmu/131_02.bvh"),
                "max_error_mm=1".into(),
            ),
            ("c3d", c3d.clone(), "mean_error_mm=3&codec=quant".into()),
            (
                "trc",
                corpus_bytes("trc/TRCSamples__Knee.trc"),
                "max_error_mm=0.5".into(),
            ),
            ("json", json, "max_error_mm=2&latency=frame".into()),
            ("npy", npy.clone(), "max_error_mm=1&fps=100&unit=mm".into()),
            // A mean alone: every codec competes (positions kept), and no served sample may
            // pass the default cap, 10× the mean.
            (
                "bvh",
                corpus_bytes("bvh/cmu/01_01.bvh"),
                "mean_error_mm=3&keep=positions".into(),
            ),
            // Both bounds at once, each of which can bind.
            (
                "bvh",
                corpus_bytes("bvh/cmu/131_02.bvh"),
                "max_error_mm=3&mean_error_mm=1&keep=positions".into(),
            ),
        ];
        let mut ids = Vec::new();
        for (kind, bytes, query) in &uploads {
            let (status, report) = srv
                .post(
                    &format!("{query}&name={kind}&library=lib&tags=a,b"),
                    bytes.clone(),
                )
                .await;
            assert_eq!(status, 201, "{} {kind}: {report}", t.name);
            let id = report["id"].as_str().unwrap().to_string();
            // The bound holds on what is served, measured against the original here.
            let opts = if *kind == "npy" {
                ReadOptions {
                    unit: Some(0.001),
                    fps: Some(100.0),
                    ..Default::default()
                }
            } else {
                ReadOptions::default()
            };
            let original = load(bytes, &opts);
            let (status, headers, served) =
                srv.get(&format!("/v1/takes/{id}/frames?format=f32")).await;
            assert_eq!(status, 200);
            assert_eq!(
                headers["x-frames"].to_str().unwrap(),
                original.frame_count().to_string()
            );
            let served: Vec<f32> = served
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect();
            let s = metrics::compare(
                original.positions(),
                &served,
                original.point_count(),
                original.unit.to_mm(),
            )
            .unwrap();
            let field = |name: &str| -> Option<f64> {
                query
                    .split('&')
                    .find_map(|kv| kv.strip_prefix(name))
                    .map(|v| v.parse().unwrap())
            };
            let mean = field("mean_error_mm=");
            let max = field("max_error_mm=").unwrap_or_else(|| 10.0 * mean.unwrap());
            assert!(
                s.max_mm <= max && mean.is_none_or(|m| s.mean_mm <= m),
                "{kind} {query}: served max {} mean {} (bounds {max}, {mean:?})",
                s.max_mm,
                s.mean_mm
            );
            // The take states its bounds, the cap among them, and the max it measured.
            let (_, _, meta) = srv.get(&format!("/v1/takes/{id}")).await;
            let meta: Value = serde_json::from_slice(&meta).unwrap();
            assert_eq!(meta["max_bound_mm"].as_f64(), Some(max), "{query}");
            assert_eq!(meta["mean_bound_mm"].as_f64(), mean, "{query}");
            assert_eq!(
                meta["max_bound_is_default"].as_bool(),
                Some(!query.contains("max_error_mm")),
                "{query}"
            );
            assert!((meta["max_mm"].as_f64().unwrap() - s.max_mm).abs() < 1e-6);
            if *kind == "json" {
                assert_eq!(report["codec"], "quant", "latency=frame excludes mdtt");
            }
            ids.push((kind.to_string(), id, original));
        }

        // Ranges: frames, seconds, a subset of points, every format.
        let (_, id, original) = &ids[0];
        let w = original.point_count() * 3;
        let (_, _, full) = srv.get(&format!("/v1/takes/{id}/frames?format=f32")).await;
        let (status, h, part) = srv
            .get(&format!(
                "/v1/takes/{id}/frames?start=100&end=340&format=f32"
            ))
            .await;
        assert_eq!(status, 200);
        assert_eq!(h["x-start-frame"], "100");
        assert!(
            part == full[100 * w * 4..340 * w * 4],
            "a range equals the same frames of the whole"
        );
        // Seconds select frames whose time lies in [t0, t1) at the rate the file's was
        // written for: this take's printed 120.00048 fps is 120, so 1 s starts at frame 120
        // (at the printed rate frame 120 would be 0.999996 s, and a second 121 frames).
        let (status, h, secs) = srv
            .get(&format!("/v1/takes/{id}/frames?t0=1&t1=2&format=f32"))
            .await;
        assert_eq!(status, 200);
        let first: usize = h["x-start-frame"].to_str().unwrap().parse().unwrap();
        let n: usize = h["x-frames"].to_str().unwrap().parse().unwrap();
        assert_eq!((first, n), (120, 120));
        assert!(secs == full[first * w * 4..(first + n) * w * 4]);
        let (status, _, body) = srv
            .get(&format!(
                "/v1/takes/{id}/frames?start=5&end=7&points=Head,Hips"
            ))
            .await;
        assert_eq!(status, 200);
        let v: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(v["points"], serde_json::json!(["Head", "Hips"]));
        assert_eq!(v["frames"].as_array().unwrap().len(), 2);
        for (format, check) in [
            ("csv", &b"frame,time,"[..]),
            ("npy", &b"\x93NUMPY"[..]),
            ("trc", &b"PathFileType"[..]),
            ("json", &b"{"[..]),
        ] {
            let (status, _, body) = srv
                .get(&format!(
                    "/v1/takes/{id}/frames?start=0&end=10&format={format}"
                ))
                .await;
            assert_eq!(status, 200, "{format}");
            assert!(body.starts_with(check), "{format}");
        }
        // One JSON shape, however the format is spelled; it reads back as a take.
        let json = |format: &'static str| {
            let path = format!("/v1/takes/{id}/frames?start=3&end=9{format}");
            let srv = &srv;
            async move {
                let (status, _, body) = srv.get(&path).await;
                assert_eq!(status, 200, "{format}");
                body
            }
        };
        let plain = json("").await;
        assert_eq!(plain, json("&format=json").await);
        assert_eq!(plain, json("&format=JSON").await);
        let v: Value = serde_json::from_slice(&plain).unwrap();
        assert_eq!(
            (v["id"].as_str(), v["start"].as_u64(), v["end"].as_u64()),
            (Some(id.as_str()), Some(3), Some(9))
        );
        let read = mocapstore::motion::formats::read(&plain, &Default::default()).unwrap();
        assert_eq!(read.motion.frame_count(), 6);
        // A skeleton take keeps its animation by default: any range comes back as BVH, the
        // MOTION rows as uploaded; a point-data take cannot, and says why.
        let (status, h, body) = srv
            .get(&format!("/v1/takes/{id}/frames?start=3&end=9&format=bvh"))
            .await;
        assert_eq!(status, 200);
        assert_eq!(h["x-frames"], "6");
        let served = load(&body, &ReadOptions::default());
        assert_eq!(served.frame_count(), 6);
        assert_eq!(
            served.skeleton.unwrap().joints,
            original.skeleton.clone().unwrap().joints
        );
        let (_, c3d_id, _) = &ids[1];
        let (status, _, body) = srv
            .get(&format!("/v1/takes/{c3d_id}/frames?format=bvh"))
            .await;
        let e: Value = serde_json::from_slice(&body).unwrap();
        assert_error(status, &e, 409);
        assert!(
            e["error"]["message"]
                .as_str()
                .unwrap()
                .contains("no skeleton"),
            "{e}"
        );

        // Metadata, with the decision record.
        let (status, _, body) = srv.get(&format!("/v1/takes/{id}")).await;
        assert_eq!(status, 200);
        let meta: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(meta["tags"], serde_json::json!(["a", "b"]));
        let reason = meta["meta"]["decision"]["reason"].as_str().unwrap();
        assert!(
            reason.contains("max 1 mm") && reason.contains("keep=animation"),
            "{reason}"
        );
        assert_eq!(meta["meta"]["decision"]["keep"], "animation");
        let codec = meta["codec"].as_str().unwrap();
        assert!(["rot", "pga", "bvh-lossless"].contains(&codec), "{codec}");
        assert_eq!(
            meta["meta"]["point_names"][0], "Hips",
            "named by the skeleton"
        );

        // Bad requests: each a 4xx JSON error, and nothing stored.
        let before = (
            store.count().await.unwrap(),
            store.chunk_count().await.unwrap(),
        );
        let bvh = corpus_bytes("bvh/cmu/131_02.bvh");
        for (query, body, want) in [
            ("", b"not a mocap file".to_vec(), 422),
            ("", bvh[..bvh.len() / 3].to_vec(), 422),
            ("", Vec::new(), 400),
            ("codec=zip", bvh.clone(), 400),
            ("max_error_mm=-1", bvh.clone(), 400),
            ("max_error_mm=NaN", bvh.clone(), 400),
            ("max_error_mm=1&mean_error_mm=-1", bvh.clone(), 400),
            ("latency=soon", bvh.clone(), 400),
            ("unit=furlong", bvh.clone(), 400),
            ("fps=0", bvh.clone(), 400),
            ("", vec![0u8; 9 << 20], 413),
        ] {
            let (status, body) = srv.post(query, body).await;
            assert_error(status, &body, want);
        }
        for (path, want) in [
            ("/v1/takes/nope".to_string(), 404),
            ("/v1/takes/nope/frames".to_string(), 404),
            (format!("/v1/takes/{id}/frames?start=0&end=99999"), 416),
            (format!("/v1/takes/{id}/frames?start=9&end=3"), 400),
            (format!("/v1/takes/{id}/frames?start=x"), 400),
            (format!("/v1/takes/{id}/frames?t0=1&start=2"), 400),
            (format!("/v1/takes/{id}/frames?points=Nose"), 400),
            (format!("/v1/takes/{id}/frames?format=xls"), 400),
        ] {
            let (status, _, body) = srv.get(&path).await;
            assert_error(
                status,
                &serde_json::from_slice(&body).unwrap_or(Value::Null),
                want,
            );
        }
        assert_eq!(
            (
                store.count().await.unwrap(),
                store.chunk_count().await.unwrap()
            ),
            before
        );

        // Delete.
        assert_eq!(srv.delete(&format!("/v1/takes/{id}")).await, 204);
        assert_eq!(srv.delete(&format!("/v1/takes/{id}")).await, 404);
        let (_, _, metrics_text) = srv.get("/metrics").await;
        assert!(String::from_utf8(metrics_text)
            .unwrap()
            .contains("mocapstore_ingested_frames_total"));
        srv.stop().await;
        t.finish().await;
    }
}

#[tokio::test]
async fn fields_may_come_as_headers() {
    if corpus::for_tests().is_none() {
        return;
    }
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let body = corpus_bytes("trc/TRCSamples__Knee.trc");
    let r = srv
        .client
        .post(format!("{}/v1/takes?library=q", srv.base))
        .header("x-mocap-name", "knee")
        .header("x-mocap-library", "ignored: the query wins")
        .header("x-mocap-mean-error-mm", "2.5")
        .header("content-type", "text/x-trc")
        .body(body.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 201);
    let v: Value = r.json().await.unwrap();
    let (_, _, meta) = srv
        .get(&format!("/v1/takes/{}", v["id"].as_str().unwrap()))
        .await;
    let meta: Value = serde_json::from_slice(&meta).unwrap();
    assert_eq!(
        (meta["name"].as_str(), meta["library"].as_str()),
        (Some("knee"), Some("q"))
    );
    assert_eq!(
        (
            meta["max_bound_mm"].as_f64(),
            meta["mean_bound_mm"].as_f64()
        ),
        (Some(25.0), Some(2.5))
    );
    let r = srv
        .client
        .post(format!("{}/v1/takes", srv.base))
        .header("x-mocap-max-error-mm", "lots")
        .body(body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 400);
    srv.stop().await;
    t.finish().await;
}

/// `spca`'s torso may be named in the request (query or `x-mocap-torso`): a marker set whose
/// names it would not recognise is normalised by the points given; a name the take does
/// not have, or not three names, is a 400 naming the problem.
#[tokio::test]
async fn the_torso_for_spca_may_be_named_in_the_request() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let m = mocapstore::motion::synthetic::walker(300, 8, 100.0, 3, 0.1);
    let body = formats::write(&m, Format::Json).unwrap();
    let (status, report) = srv
        .post("codec=spca&max_error_mm=2&torso=M0,M2,M4", body.clone())
        .await;
    assert_eq!(status, 201, "{report}");
    assert_eq!(report["codec"], "spca");
    assert!(report["max_mm"].as_f64().unwrap() <= 2.0, "{report}");
    let r = srv
        .client
        .post(format!("{}/v1/takes?codec=spca", srv.base))
        .header("x-mocap-torso", "M1, M3, M5")
        .body(body.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 201);
    for (torso, says) in [
        ("M0,M2,C7", "\"C7\""),
        ("M0,M2", "three"),
        ("M0,M0,M1", "three"),
    ] {
        let (status, err) = srv
            .post(&format!("codec=spca&torso={torso}"), body.clone())
            .await;
        assert_error(status, &err, 400);
        let message = err["error"]["message"].as_str().unwrap();
        assert!(message.contains(says), "{torso}: {message}");
    }
    srv.stop().await;
    t.finish().await;
}
