//! Issue 49: glTF in. Every GLB of the corpus (five Mixamo animations and the Y Bot
//! character with its skin) ingested with defaults is a skeleton take whose joints, read
//! back in metres, lie where pygltflib's evaluation puts the same nodes
//! (scripts/gltf-eval.py, not our code), at every key. A file of two animations is two
//! takes; broken glTF is a 422 naming the reason.

use crate::common;

use mocapstore::corpus;

#[tokio::test(flavor = "multi_thread")]
async fn every_corpus_glb_is_stored_as_a_player_shows_it() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let mut files: Vec<_> = std::fs::read_dir(root.join("gltf"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "glb"))
        .collect();
    files.sort();
    assert!(files.len() >= 6, "{files:?}");
    for path in &files {
        let file = path.file_name().unwrap().to_string_lossy().to_string();
        let (status, report) = srv
            .post(&format!("name={file}"), std::fs::read(path).unwrap())
            .await;
        assert_eq!(status, 201, "{file}: {report}");
        let id = report["id"].as_str().unwrap();
        let (_, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
        let theirs = common::script(&python, "gltf-eval.py", [path]);
        let times: Vec<f64> = theirs["times"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t.as_f64().unwrap())
            .collect();
        let fps = take["fps"].as_f64().unwrap();
        assert_eq!(take["source_format"], "glb", "{file}: {take}");
        assert!(take["skeleton"].is_string(), "{file}: a skeleton take");
        assert_eq!(take["metres_per_unit"], 1.0, "{file}: glTF is metres");
        assert_eq!(take["body"]["up"], "y", "{file}: {take}");
        assert_eq!(take["body"]["convention"], "mixamo", "{file}: {take}");
        // The keys are evenly spaced: one frame per key, at the keys' rate.
        assert_eq!(take["frames"], times.len(), "{file}");
        let spacing = (times[times.len() - 1] - times[0]) / (times.len() - 1).max(1) as f64;
        assert!((fps * spacing - 1.0).abs() < 1e-3, "{file}: {fps} fps");
        let bound_m = take["max_mm"].as_f64().unwrap() * 1e-3;
        let (status, ours) = srv.get_json(&format!("/v1/takes/{id}/frames?unit=m")).await;
        assert_eq!(status, 200, "{ours}");
        let (compared, worst) = common::against_gltf_eval(&ours, &theirs, fps, times[0]);
        eprintln!(
            "{file}: {} joints, {} frames at {fps} fps; {compared} positions, worst {:.4} mm",
            take["points"],
            take["frames"],
            worst * 1e3
        );
        assert_eq!(
            compared,
            times.len() * take["points"].as_u64().unwrap() as usize,
            "{file}"
        );
        assert!(
            worst <= bound_m + 1e-6,
            "{file}: {worst} m over {bound_m} m"
        );
        // Stored raw, the reading itself: what the player shows, to float precision.
        let (status, raw) = srv
            .post(
                &format!("name={file}.raw&codec=raw"),
                std::fs::read(path).unwrap(),
            )
            .await;
        assert_eq!(status, 201, "{file}: {raw}");
        let (_, exact) = srv
            .get_json(&format!(
                "/v1/takes/{}/frames?unit=m",
                raw["id"].as_str().unwrap()
            ))
            .await;
        let (_, read_worst) = common::against_gltf_eval(&exact, &theirs, fps, times[0]);
        eprintln!("{file}: read (codec raw) worst {:.5} mm", read_worst * 1e3);
        assert!(
            read_worst < 1e-5,
            "{file}: read {read_worst} m from the player's"
        );
        if file.contains("ybot") {
            // The character's skin names 67 joints; its two meshes are not motion.
            assert_eq!(take["points"], 67, "{take}");
            let warned = report["warnings"].to_string();
            assert!(warned.contains("meshes"), "{warned}");
        }
    }
    srv.stop().await;
    t.finish().await;
}

/// A `.gltf` with its buffer embedded, of one node and `animations` translation
/// animations of two LINEAR keys each (0 → 1 m along X over 1 s, then 2 m, ...).
fn two_animation_gltf(animations: usize) -> Vec<u8> {
    use base64::Engine;
    let mut blob = Vec::new();
    for v in [0.0f32, 1.0] {
        blob.extend(v.to_le_bytes());
    }
    let mut accessors = vec![serde_json::json!({
        "bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR",
        "min": [0.0], "max": [1.0]
    })];
    let mut anims = Vec::new();
    for a in 0..animations {
        let offset = blob.len();
        for v in [0.0f32, 0.0, 0.0, (a + 1) as f32, 0.0, 0.0] {
            blob.extend(v.to_le_bytes());
        }
        accessors.push(serde_json::json!({
            "bufferView": 0, "byteOffset": offset, "componentType": 5126, "count": 2,
            "type": "VEC3"
        }));
        anims.push(serde_json::json!({
            "name": format!("move{a}"),
            "samplers": [{"input": 0, "output": a + 1}],
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}]
        }));
    }
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&blob)
    );
    serde_json::to_vec(&serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "mover"}],
        "buffers": [{"byteLength": blob.len(), "uri": uri}],
        "bufferViews": [{"buffer": 0, "byteLength": blob.len()}],
        "accessors": accessors,
        "animations": anims
    }))
    .unwrap()
}

#[tokio::test(flavor = "multi_thread")]
async fn each_animation_of_a_file_is_a_take_and_broken_gltf_is_refused() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let file = two_animation_gltf(2);
    let (status, report) = srv.post("name=clip&fps=10", file.clone()).await;
    assert_eq!(status, 201, "{report}");
    assert_eq!(report["name"], "clip/move0", "{report}");
    let more = report["more"].as_array().expect("the second animation");
    assert_eq!(more.len(), 1, "{report}");
    assert_eq!(more[0]["name"], "clip/move1");
    for (r, reach) in [(&report, 1.0), (&more[0], 2.0)] {
        let id = r["id"].as_str().unwrap();
        let (_, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
        assert_eq!(take["frames"], 11, "1 s at 10 fps: {take}");
        assert_eq!(
            take["labels"]["animation"],
            r["name"].as_str().unwrap()[5..]
        );
        let (_, frames) = srv.get_json(&format!("/v1/takes/{id}/frames?unit=m")).await;
        let x = |f: usize| frames["frames"][f][0][0].as_f64().unwrap();
        assert!((x(10) - reach).abs() < 1e-3 && (x(5) - reach / 2.0).abs() < 1e-3);
    }
    // One asked for by name; an unknown one named with the file's.
    let (status, one) = srv.post("name=only&animation=move1", file.clone()).await;
    assert_eq!(status, 201, "{one}");
    assert_eq!(one["name"], "only/move1");
    assert!(one.get("more").is_none(), "{one}");
    let (status, e) = srv.post("name=x&animation=jump", file.clone()).await;
    assert_eq!(status, 422, "{e}");
    assert!(e.to_string().contains("move0, move1"), "{e}");

    // Broken: cut short, an index past the data, a buffer in another file.
    let doc: serde_json::Value = serde_json::from_slice(&file).unwrap();
    let mut past = doc.clone();
    past["accessors"][1]["count"] = 1000.into();
    let mut outside = doc.clone();
    outside["buffers"][0]["uri"] = "walk.bin".into();
    let mut cycle = doc.clone();
    cycle["nodes"][0]["children"] = serde_json::json!([0]);
    // A chain of nodes deeper than any skeleton (the limit is 512), and a count no file
    // holds.
    let mut deep = doc.clone();
    deep["nodes"] = (0..2000)
        .map(|i| serde_json::json!({"name": format!("n{i}"), "children": if i < 1999 { vec![i + 1] } else { vec![] }}))
        .collect();
    let mut huge = doc.clone();
    huge["accessors"][0]["count"] = u64::MAX.into();
    // Key times of no buffer view (zeros, so one frame) in a count no take could hold.
    let mut zeros = doc.clone();
    zeros["accessors"][0] =
        serde_json::json!({"componentType": 5126, "count": 1u64 << 40, "type": "SCALAR"});
    for (what, bad) in [
        ("cut", file[..file.len() / 2].to_vec()),
        ("past", serde_json::to_vec(&past).unwrap()),
        ("outside", serde_json::to_vec(&outside).unwrap()),
        ("cycle", serde_json::to_vec(&cycle).unwrap()),
        ("deep", serde_json::to_vec(&deep).unwrap()),
        ("huge", serde_json::to_vec(&huge).unwrap()),
        ("zeros", serde_json::to_vec(&zeros).unwrap()),
        ("glb", b"glTF\x02\0\0\0\xff\xff\0\0".to_vec()),
    ] {
        let (status, err) = srv.post("name=bad", bad).await;
        assert!(status == 422 || status == 400, "{what}: {status} {err}");
        let said = err.to_string().to_lowercase();
        assert!(
            said.contains("gltf") || said.contains("json") || said.contains("limit"),
            "{what}: {err}"
        );
    }
    srv.stop().await;
    t.finish().await;
}
