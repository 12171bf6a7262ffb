//! Issue 49: FBX in. A Mixamo FBX ingested with defaults is stored as a skeleton take whose
//! joints, read back in metres, lie where an independent reader puts them: pygltflib's
//! evaluation of the GLB Mixamo converted from the same animation (scripts/gltf-eval.py,
//! not our code). Broken FBX is a 422 naming the reason, never a crash.

use crate::common;

use mocapstore::corpus;

#[tokio::test(flavor = "multi_thread")]
async fn a_mixamo_fbx_is_stored_as_its_author_saw_it() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    let fbx = std::fs::read(root.join("fbx/mixamo_breathing_idle.fbx")).unwrap();
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let (status, report) = srv.post("name=idle", fbx.clone()).await;
    assert_eq!(status, 201, "{report}");
    let id = report["id"].as_str().unwrap().to_string();
    let (_, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
    assert_eq!(take["source_format"], "fbx", "{take}");
    assert!(take["skeleton"].is_string(), "a skeleton take: {take}");
    assert_eq!(take["fps"], 60.0);
    assert_eq!(take["frames"], 596);
    assert_eq!(take["points"], 37);
    assert_eq!(
        take["metres_per_unit"], 0.01,
        "the file's UnitScaleFactor (cm)"
    );
    assert_eq!(take["body"]["up"], "y", "{take}");
    assert_eq!(take["body"]["convention"], "mixamo", "{take}");
    assert_eq!(take["body"]["unplaced"], serde_json::json!([]), "{take}");
    let bound_m = take["max_mm"].as_f64().unwrap() * 1e-3;
    let (status, ours) = srv.get_json(&format!("/v1/takes/{id}/frames?unit=m")).await;
    assert_eq!(status, 200, "{ours}");

    let glb = root.join("gltf/mixamo_breathing_idle.glb");
    let theirs = common::script(&python, "gltf-eval.py", [&glb]);
    // The GLB keys at 24 fps; those that fall on one of the take's 60 fps frames.
    let (compared, worst) = common::against_gltf_eval(&ours, &theirs, 60.0, 0.0);
    eprintln!("FBX vs the GLB's evaluation: {compared} joint positions, worst {worst:.6} m");
    assert!(compared > 3000, "{compared}");
    assert!(
        worst <= bound_m + 1e-6,
        "worst {worst} m over the bound {bound_m} m"
    );

    // Broken: cut short, or only the magic: a 422 naming FBX.
    for bad in [
        &fbx[..fbx.len() / 3],
        &fbx[..40],
        b"Kaydara FBX Binary  \0\x1a\0".as_slice(),
    ] {
        let (status, err) = srv.post("name=bad", bad.to_vec()).await;
        assert_eq!(status, 422, "{err}");
        assert!(err.to_string().contains("FBX"), "{err}");
    }
    srv.stop().await;
    t.finish().await;
}
