//! Issue 48: what a take's GLB shows against an independent reading of its source file.
//! The service's own frames are not the reference (they share its transforms): the source
//! BVH's forward kinematics by `scripts/bvh-fk.py` is, turned from the up axis the
//! manifest (`tests/bodies/up.csv`) gives to glTF's +Y.

use crate::common;
use crate::manifest::manifest;

use std::path::Path;

use mocapstore::corpus;
use mocapstore::motion::body::Axis;
use nalgebra::{Matrix3, Vector3};
use serde_json::Value;

/// Runs a script of `scripts/` with the test Python: its JSON line.
fn script(python: &Path, name: &str, args: &[&Path]) -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts")
        .join(name);
    let o = std::process::Command::new(python)
        .arg(path)
        .args(args)
        .output()
        .unwrap();
    serde_json::from_slice(o.stdout.trim_ascii()).unwrap_or_else(|_| {
        panic!(
            "{name} said {} {}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    })
}

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
        let shown = script(&python, "gltf-eval.py", &[&file]);
        let source = script(&python, "bvh-fk.py", &[&path]);
        // The manifest's up turned to +Y: a rotation of whole axes.
        let turn: Matrix3<f64> = want.up.turn_to(Axis::Y).unwrap_or_else(Matrix3::identity);
        let nodes: Vec<&str> = shown["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| n.as_str().unwrap())
            .collect();
        let names: Vec<&str> = source["names"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| n.as_str().unwrap())
            .collect();
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
