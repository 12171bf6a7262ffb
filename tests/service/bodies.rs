//! Issue 48: what a take's GLB shows against an independent reading of its source file.
//! The service's own frames are not the reference (they share its transforms): the source
//! BVH's forward kinematics by `scripts/bvh-fk.py` is, turned from the up axis the
//! manifest (`tests/bodies/up.csv`) gives to glTF's +Y.

use crate::common;
use crate::manifest::manifest;

use mocapstore::corpus;
use mocapstore::motion::body::Axis;
use nalgebra::{Matrix3, Vector3};
use serde_json::Value;

fn point(v: &Value) -> Vector3<f64> {
    Vector3::new(
        v[0].as_f64().unwrap(),
        v[1].as_f64().unwrap(),
        v[2].as_f64().unwrap(),
    )
}

/// The corpus BVH this test reads (those the reference parser reads whole): one in
/// `every` of each dataset, sorted (all with `MOCAP_FULL_SWEEP=1`), and every fourth walk,
/// the takes that lay on their side before.
fn chosen(entries: &[corpus::Entry], every: usize) -> Vec<String> {
    let all = std::env::var("MOCAP_FULL_SWEEP").is_ok_and(|v| v == "1");
    let mut out = Vec::new();
    for d in ["bvh/cmu/", "bvh/bandai/", "bvh/misc/"] {
        let mut files: Vec<&str> = entries
            .iter()
            .filter(|e| e.path.starts_with(d) && e.reference_ok != Some(false))
            .map(|e| e.path.as_str())
            .collect();
        files.sort();
        let mut walks = 0;
        for (i, p) in files.into_iter().enumerate() {
            let walk = p.to_lowercase().contains("walk");
            if all || i % every == 0 || walk && walks % 4 == 0 {
                out.push(p.to_string());
            }
            walks += usize::from(walk);
        }
    }
    out
}

/// Every chosen corpus BVH as GLB (pygltflib's evaluation) against the source's own FK
/// turned to +Y up and scaled to metres: every joint within the take's bound; and the head
/// above both ankles along +Y in every frame, but where the manifest says the body is
/// upside down. CI reads one BVH in 8 and every walk in 4; `MOCAP_FULL_SWEEP=1` reads all.
#[tokio::test(flavor = "multi_thread")]
async fn glb_stands_up_as_an_independent_reading_of_the_source() {
    let Some((root, entries)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    let truth = manifest();
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let dir = std::env::temp_dir().join(format!("mocapstore-bodies-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (mut checked, mut worst) = (0, 0.0f64);
    for rel in chosen(&entries, 8) {
        let path = root.join(&rel);
        let want = truth
            .get(&rel)
            .unwrap_or_else(|| panic!("{rel} not in up.csv"));
        let (status, report) = srv
            .post("lenient=true", std::fs::read(&path).unwrap())
            .await;
        assert_eq!(status, 201, "{rel}: {report}");
        let id = report["id"].as_str().unwrap().to_string();
        let bound_m = report["max_mm"].as_f64().unwrap() * 1e-3;
        let (_, _, take) = srv.get(&format!("/v1/takes/{id}")).await;
        let take: Value = serde_json::from_slice(&take).unwrap();
        let metres_per_unit = take["metres_per_unit"].as_f64().unwrap();
        let (status, _, glb) = srv.get(&format!("/v1/takes/{id}/frames?format=glb")).await;
        assert_eq!(status, 200, "{rel}: {}", String::from_utf8_lossy(&glb));
        let file = dir.join("take.glb");
        std::fs::write(&file, &glb).unwrap();
        let shown = common::script(&python, "gltf-eval.py", [&file]);
        let source = common::script(&python, "bvh-fk.py", [&path]);
        // The manifest's up turned to +Y: a rotation of whole axes.
        let turn: Matrix3<f64> = want.up.turn_to(Axis::Y).unwrap_or_else(Matrix3::identity);
        let nodes = common::strings(&shown["nodes"]);
        let names = common::strings(&source["names"]);
        let pairs: Vec<(usize, usize)> = names
            .iter()
            .enumerate()
            .filter_map(|(i, n)| nodes.iter().position(|m| m == n).map(|j| (i, j)))
            .collect();
        assert!(
            pairs.len() * 10 >= names.len() * 9,
            "{rel}: {} of {} joints found among the GLB's nodes",
            pairs.len(),
            names.len()
        );
        let fk = source["positions"].as_array().unwrap();
        let glb = shown["positions"].as_array().unwrap();
        assert_eq!(fk.len(), glb.len(), "{rel}: frames");
        let tol = bound_m + 1e-4;
        for (f, (a, b)) in fk.iter().zip(glb).enumerate() {
            for &(i, j) in &pairs {
                let expected = turn * point(&a[i]) * metres_per_unit;
                let d = (expected - point(&b[j])).norm();
                worst = worst.max(d);
                assert!(
                    d <= tol,
                    "{rel} frame {f} {}: {d:.4} m off (bound {tol:.4})",
                    names[i]
                );
            }
        }
        // The head above both ankles, as the take's body names them (the two-joint toy
        // has neither: tests/bodies.rs holds it is no body).
        let roles = &take["body"]["roles"];
        let node = |role: &str| -> Option<usize> {
            let name = roles[role][0].as_str()?;
            nodes.iter().position(|n| *n == name)
        };
        let (Some(head), Some(l), Some(r)) =
            (node("head"), node("left_ankle"), node("right_ankle"))
        else {
            assert!(
                rel.ends_with("two_joint_toy.bvh"),
                "{rel}: no head or ankles"
            );
            checked += 1;
            continue;
        };
        let ankles = [l, r];
        for (f, b) in glb.iter().enumerate() {
            if want.upside_down_at(f) {
                continue;
            }
            let y = |n: usize| b[n][1].as_f64().unwrap();
            for a in ankles {
                assert!(
                    y(head) > y(a),
                    "{rel} frame {f}: the head is below an ankle"
                );
            }
        }
        checked += 1;
    }
    let _ = std::fs::remove_dir_all(&dir);
    eprintln!("{checked} corpus BVH as GLB against their own FK: worst joint {worst:.5} m");
    assert!(checked >= 20, "{checked}");
    srv.stop().await;
    t.finish().await;
}

/// PATCH `body` as a user sends it: the answer's status and body.
async fn correct(srv: &common::Server, id: &str, body: Value) -> (u16, Value) {
    let r = srv
        .client
        .patch(format!("{}/v1/takes/{id}", srv.base))
        .json(&serde_json::json!({ "body": body }))
        .send()
        .await
        .unwrap();
    (r.status().as_u16(), r.json().await.unwrap())
}

/// Points of a JSON range answer: frame `f`, point `name`.
fn at(answer: &Value, f: usize, name: &str) -> Vector3<f64> {
    let i = answer["points"]
        .as_array()
        .unwrap()
        .iter()
        .position(|n| n == name)
        .unwrap();
    point(&answer["frames"][f][i])
}

/// A take whose body nothing tells (floating points, no names a convention knows, a
/// format with no convention) has `up: null` with the reason; glTF and in-place answer 409
/// naming what to give; PATCH gives it, and they answer. Corrected roles move the root
/// that in-place holds, on this server and on another sharing the database, whose cached
/// decoder still held the old body. What makes no sense is a 400 naming it.
#[tokio::test(flavor = "multi_thread")]
async fn a_body_nothing_tells_is_given_by_patch() {
    let t = common::sqlite().await;
    let (a, b) = (
        common::start(t.store.clone(), 64 << 20).await,
        common::start(t.store.clone(), 64 << 20).await,
    );
    // Three points drifting 4 m up in the air, along x.
    let frames: Vec<Value> = (0..120)
        .map(|f| {
            let x = f as f64 * 0.01;
            serde_json::json!([[x, 4.0, 0.0], [x + 0.2, 4.5, 0.1], [x - 0.1, 4.2, 0.3]])
        })
        .collect();
    let doc =
        serde_json::json!({"fps": 60, "unit": "m", "points": ["p", "q", "r"], "frames": frames});
    let (status, report) = a.post("name=floating", doc.to_string().into_bytes()).await;
    assert_eq!(status, 201, "{report}");
    let id = report["id"].as_str().unwrap().to_string();
    let (_, take) = a.get_json(&format!("/v1/takes/{id}")).await;
    assert_eq!(take["body"]["up"], Value::Null, "{take}");
    assert!(
        take["body"]["reason"].as_str().unwrap().contains("up="),
        "{take}"
    );
    for query in ["format=glb", "root=in-place", "up=z"] {
        let (status, err) = a.get_json(&format!("/v1/takes/{id}/frames?{query}")).await;
        assert_eq!(status, 409, "{query}: {err}");
        assert!(err.to_string().contains("PATCH"), "{query}: {err}");
    }
    // Nonsense is named.
    for (bad, names) in [
        (serde_json::json!({"up": "w"}), "w"),
        (serde_json::json!({"up": "y", "forward": "-y"}), "forward"),
        (serde_json::json!({"roles": {"pelvis": ["nope"]}}), "nope"),
        (serde_json::json!({"roles": {"elbow": ["p"]}}), "elbow"),
        (serde_json::json!({"up": null}), "null"),
        (serde_json::json!({"down": "y"}), "down"),
    ] {
        let (status, err) = correct(&a, &id, bad.clone()).await;
        assert_eq!(status, 400, "{bad}: {err}");
        assert!(err.to_string().contains(names), "{bad}: {err}");
    }
    // A refused correction changes nothing, the rest of its PATCH included.
    let r = a
        .client
        .patch(format!("{}/v1/takes/{id}", a.base))
        .json(&serde_json::json!({"name": "renamed", "body": {"roles": {"pelvis": ["nope"]}}}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 400);
    let (_, take) = a.get_json(&format!("/v1/takes/{id}")).await;
    assert_eq!(take["name"], "floating", "{take}");
    assert_eq!(take["body"]["roles"]["pelvis"], Value::Null, "{take}");
    // Up given, and the pelvis: glTF and in-place answer.
    let (status, take) = correct(
        &a,
        &id,
        serde_json::json!({"up": "y", "roles": {"pelvis": ["p"]}}),
    )
    .await;
    assert_eq!(status, 200, "{take}");
    assert_eq!(take["body"]["up"], "y", "{take}");
    assert_eq!(take["body"]["up_from"], "given", "{take}");
    assert_eq!(take["body"]["roles"]["pelvis"], serde_json::json!(["p"]));
    assert_eq!(take["body"]["given"], serde_json::json!(["pelvis"]));
    let (status, _, _) = a.get(&format!("/v1/takes/{id}/frames?format=glb")).await;
    assert_eq!(status, 200);
    // Server b caches a decoder with p as the pelvis…
    let (status, held) = b
        .get_json(&format!("/v1/takes/{id}/frames?root=in-place"))
        .await;
    assert_eq!(status, 200, "{held}");
    assert!(at(&held, 100, "p").x.abs() < 1e-3, "{held}");
    // …a moves the pelvis to q, and b's next answer holds q in place.
    let (status, take) = correct(&a, &id, serde_json::json!({"roles": {"pelvis": ["q"]}})).await;
    assert_eq!(status, 200, "{take}");
    assert_eq!(take["body"]["up"], "y", "an up given before stays: {take}");
    let (_, held) = b
        .get_json(&format!("/v1/takes/{id}/frames?root=in-place"))
        .await;
    let (p, q) = (at(&held, 100, "p"), at(&held, 100, "q"));
    assert!(q.x.abs() < 1e-3 && q.z.abs() < 1e-3, "q held: {held}");
    assert!((p.x + 0.2).abs() < 1e-3, "p where it is beside q: {p:?}");
    // The corrected body is in the record: a server started after reads it.
    let c = common::start(t.store.clone(), 64 << 20).await;
    let (_, take) = c.get_json(&format!("/v1/takes/{id}")).await;
    assert_eq!(
        take["body"]["roles"]["pelvis"],
        serde_json::json!(["q"]),
        "{take}"
    );
    assert_eq!(take["body"]["up"], "y");
    for s in [a, b, c] {
        s.stop().await;
    }
    t.finish().await;
}

/// The body of `id` as GET /v1/takes/{id} shows it.
async fn body_of(srv: &common::Server, id: &str) -> Value {
    let (status, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
    assert_eq!(status, 200, "{take}");
    take["body"].clone()
}

/// A take stored before bodies were kept (its record without axes) gets its body at its
/// first read, from a sample of its chunks and its skeleton's joints (the floor under the
/// toes' end sites, as at ingest), stored, its bitstream untouched; a correction keeps the
/// floor where it was.
#[tokio::test(flavor = "multi_thread")]
async fn a_take_stored_before_gets_its_body_at_its_first_read() {
    let Some((root, entries)) = corpus::for_tests() else {
        return;
    };
    let mut walks: Vec<&str> = entries
        .iter()
        .filter(|e| e.path.starts_with("bvh/bandai/") && e.path.contains("walk"))
        .map(|e| e.path.as_str())
        .collect();
    walks.sort();
    let rel = walks.first().expect("a Bandai walk in the corpus");
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let (status, report) = srv
        .post("lenient=true", std::fs::read(root.join(rel)).unwrap())
        .await;
    assert_eq!(status, 201, "{rel}: {report}");
    let id = report["id"].as_str().unwrap().to_string();
    let at_ingest = body_of(&srv, &id).await;
    assert_eq!(at_ingest["up"], "y", "{rel}: {at_ingest}");
    let floor = at_ingest["floor_m"].as_f64().unwrap();

    // As a take stored before bodies were kept: no axes in its meta.
    let mut row = t.store.get(&id).await.unwrap().unwrap();
    let text = |meta: &[u8]| mocapstore::store::packed::unpack(meta).unwrap();
    let mut meta: Value = serde_json::from_str(&text(&row.meta)).unwrap();
    meta.as_object_mut().unwrap().remove("axes").unwrap();
    row.meta = mocapstore::store::packed::pack(&meta.to_string()).unwrap();
    assert!(t.store.set_meta(&row).await.unwrap());
    let before = t.store.get(&id).await.unwrap().unwrap();
    assert!(!text(&before.meta).contains("\"axes\""));

    let derived = body_of(&srv, &id).await;
    for k in ["up", "forward", "up_from", "convention"] {
        assert_eq!(derived[k], at_ingest[k], "{rel} {k}: {derived}");
    }
    let d = derived["floor_m"].as_f64().unwrap();
    assert!(
        (d - floor).abs() < 0.02,
        "{rel}: floor {d} m, at ingest {floor} m"
    );
    let after = t.store.get(&id).await.unwrap().unwrap();
    assert!(text(&after.meta).contains("\"axes\""), "stored once");
    assert_eq!(after.body_rev, before.body_rev + 1);
    assert_eq!(
        (&after.header, after.totals.stored_bytes, &after.codec),
        (&before.header, before.totals.stored_bytes, &before.codec),
        "no bitstream changes"
    );
    // Read again: nothing derived or written.
    body_of(&srv, &id).await;
    assert_eq!(
        t.store.get(&id).await.unwrap().unwrap().body_rev,
        after.body_rev
    );

    // A correction of forward derives the rest again: the floor stays under the toes.
    let (status, take) = correct(&srv, &id, serde_json::json!({"forward": "-x"})).await;
    assert_eq!(status, 200, "{take}");
    assert_eq!(take["body"]["forward"], "-x");
    let c = take["body"]["floor_m"].as_f64().unwrap();
    assert!(
        (c - floor).abs() < 0.02,
        "{rel}: corrected floor {c} m, at ingest {floor} m"
    );
    srv.stop().await;
    t.finish().await;
}

/// A live stream's take has its body from its first chunk (a glTF of the live take stands
/// up by it), and from all of it once it finishes; a body corrected after the finish is
/// what every later read turns by.
#[tokio::test(flavor = "multi_thread")]
async fn a_live_take_has_its_body_from_its_first_chunk() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    // A dancer in metres, its first second X-up (its +Y turned to +X), the three after Z-up
    // (+Y turned to +Z): the first chunk stands along x, the take along z.
    let m = mocapstore::motion::synthetic::dancer(480, 120.0, 5);
    let k = m.unit.metres_per_unit as f32;
    let w = m.point_count() * 3;
    let frames: Vec<f32> = m
        .positions()
        .chunks_exact(3)
        .enumerate()
        .flat_map(|(i, p)| {
            if i < 120 * w / 3 {
                [p[1] * k, -p[0] * k, p[2] * k]
            } else {
                [p[0] * k, -p[2] * k, p[1] * k]
            }
        })
        .collect();
    let (status, _, info) = srv
        .post_json(
            "/v1/streams",
            &serde_json::json!({"name": "live dancer", "fps": 120.0, "points": m.point_names,
                    "unit": "m", "max_error_mm": 1.0, "chunk_seconds": 1.0,
                    "reencode_on_finish": true}),
        )
        .await;
    assert_eq!(status, 201, "{info}");
    let id = info["id"].as_str().unwrap().to_string();
    let send = |from: usize, to: usize| {
        let body: Vec<u8> = frames[from * w..to * w]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        srv.client
            .post(format!("{}/v1/streams/{id}/frames", srv.base))
            .header("content-type", "application/octet-stream")
            .body(body)
            .send()
    };
    assert_eq!(send(0, 60).await.unwrap().status().as_u16(), 200);
    assert_eq!(
        body_of(&srv, &id).await,
        Value::Null,
        "no frame committed yet"
    );
    assert_eq!(send(60, 240).await.unwrap().status().as_u16(), 200);
    let live = body_of(&srv, &id).await;
    assert_eq!(live["up"], "x", "{live}");
    let (status, _, glb) = srv.get(&format!("/v1/takes/{id}/frames?format=glb")).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&glb));
    assert_eq!(send(240, 480).await.unwrap().status().as_u16(), 200);
    let (status, _, row) = srv
        .post_json(&format!("/v1/streams/{id}/finish"), &serde_json::json!({}))
        .await;
    assert_eq!(status, 200, "{row}");
    let done = body_of(&srv, &id).await;
    assert_eq!(
        (&done["up"], &done["up_from"]),
        (&Value::from("z"), &Value::from("anatomy"))
    );
    // The body stays as corrected: the finish's re-encoding wrote before it, or not at all.
    let (status, take) = correct(&srv, &id, serde_json::json!({"up": "-x"})).await;
    assert_eq!(status, 200, "{take}");
    let stored = t.store.get(&id).await.unwrap().unwrap();
    let meta = mocapstore::store::packed::unpack(&stored.meta).unwrap();
    assert!(meta.contains("\"up\":\"-x\""), "{meta}");
    assert_eq!(body_of(&srv, &id).await["up"], "-x");
    srv.stop().await;
    t.finish().await;
}
