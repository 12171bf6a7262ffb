//! Takes that open where people work (issue 35): resampling, root motion, axes and units on
//! the read path, and glTF out, checked against the full-rate decode and against
//! independent readers (the Khronos glTF validator, pygltflib).

use crate::common;

use std::path::{Path, PathBuf};

use mocapstore::corpus;
use serde_json::Value;

/// Frames of samples, `None` where missing.
type Frames = Vec<Vec<Option<[f64; 3]>>>;

/// A JSON answer's point names and frames.
fn samples(body: &[u8]) -> (Vec<String>, Frames) {
    let v: Value = serde_json::from_slice(body).unwrap();
    let names = v["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap().to_string())
        .collect();
    let frames = v["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            f.as_array()
                .unwrap()
                .iter()
                .map(|p| {
                    p.as_array().map(|a| {
                        [
                            a[0].as_f64().unwrap(),
                            a[1].as_f64().unwrap(),
                            a[2].as_f64().unwrap(),
                        ]
                    })
                })
                .collect()
        })
        .collect();
    (names, frames)
}

fn header(h: &reqwest::header::HeaderMap, name: &str) -> String {
    h.get(name).unwrap().to_str().unwrap().to_string()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The max error a take's report measured, in its units (`metres_per_unit`, as its JSON
/// answers state it).
fn measured_max(report: &Value, metres_per_unit: f64) -> f64 {
    report["max_mm"].as_f64().unwrap() * 1e-3 / metres_per_unit
}

/// The metres per unit a JSON answer states.
fn mpu(body: &[u8]) -> f64 {
    let v: Value = serde_json::from_slice(body).unwrap();
    v["metres_per_unit"].as_f64().unwrap()
}

#[tokio::test(flavor = "multi_thread")]
async fn resampling_root_motion_axes_and_units() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;

    // A CMU take at 120 fps.
    let bvh = std::fs::read(root.join("bvh/cmu/131_01.bvh")).unwrap();
    let (status, report) = srv.post("name=cmu", bvh).await;
    assert_eq!(status, 201, "{report}");
    let id = report["id"].as_str().unwrap().to_string();
    let (status, _, body) = srv.get(&format!("/v1/sequences/{id}/frames")).await;
    assert_eq!(status, 200);
    let (names, full) = samples(&body);
    let mpu = mpu(&body);
    let bound = measured_max(&report, mpu);
    assert_eq!(full.len(), 994);

    // 120 → 30 fps: every fourth frame of the full-rate decode.
    let (status, h, body) = srv.get(&format!("/v1/sequences/{id}/frames?fps=30")).await;
    assert_eq!(status, 200);
    assert_eq!(header(&h, "x-fps"), "30");
    // CMU's frame time, 0.0083333 s, is 120.00048 fps: the grid is 120's.
    let source: f64 = header(&h, "x-source-fps").parse().unwrap();
    assert!((source - 120.0).abs() < 1e-3, "{source}");
    assert_eq!(header(&h, "x-frames"), "249");
    let (_, quarter) = samples(&body);
    assert_eq!(quarter.len(), 249);
    for (k, f) in quarter.iter().enumerate() {
        for (p, s) in f.iter().enumerate() {
            let d = dist(s.unwrap(), full[k * 4][p].unwrap());
            assert!(d <= 1e-4 * bound, "frame {k} point {p}: {d}");
        }
    }
    // A range resampled is the same frames as the whole take's (its grid starts at t0).
    let (status, _, body) = srv
        .get(&format!(
            "/v1/sequences/{id}/frames?fps=30&start=400&end=600"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let (_, part) = samples(&body);
    assert_eq!(part.len(), 50);
    assert_eq!(part[0], quarter[100]);

    // In place: the root's horizontal path is zero, its height and every point relative to
    // it unchanged (f32 answers: within a few ulps of centimetres).
    let (status, _, body) = srv
        .get(&format!("/v1/sequences/{id}/frames?root=in-place"))
        .await;
    assert_eq!(status, 200);
    let (_, inplace) = samples(&body);
    for (f, (a, b)) in full.iter().zip(&inplace).enumerate() {
        let (ra, rb) = (a[0].unwrap(), b[0].unwrap());
        assert!(rb[0] == 0.0 && rb[2] == 0.0, "frame {f}: {rb:?}");
        assert_eq!(ra[1], rb[1]);
        for (pa, pb) in a.iter().zip(b).skip(1) {
            let (pa, pb) = (pa.unwrap(), pb.unwrap());
            for k in 0..3 {
                assert!(
                    ((pa[k] - ra[k]) - (pb[k] - rb[k])).abs() < 1e-3,
                    "frame {f}"
                );
            }
        }
    }
    // Extracted: the same, and the path as a `root_motion` point.
    let (status, _, body) = srv
        .get(&format!(
            "/v1/sequences/{id}/frames?root=extract&points=Hips,LeftWrist"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let (named, extract) = samples(&body);
    assert_eq!(named, ["Hips", "LeftWrist", "root_motion"]);
    let hand = names.iter().position(|n| n == "LeftWrist").unwrap();
    for (f, e) in extract.iter().enumerate() {
        let (hips, path) = (e[0].unwrap(), e[2].unwrap());
        assert_eq!(path[1], 0.0);
        let original = full[f][0].unwrap();
        assert!(dist([hips[0] + path[0], hips[1], hips[2] + path[2]], original) < 1e-3);
        let h = full[f][hand].unwrap();
        let got = e[1].unwrap();
        assert!(dist([got[0] + path[0], got[1], got[2] + path[2]], h) < 1e-3);
    }

    // Z up, in metres: (x, y, z) cm → (x, −z, y) / 100.
    let (status, h, body) = srv
        .get(&format!("/v1/sequences/{id}/frames?up=z&unit=m&end=50"))
        .await;
    assert_eq!(status, 200);
    assert_eq!(header(&h, "x-metres-per-unit"), "1");
    let (_, turned) = samples(&body);
    for (a, b) in full.iter().zip(&turned) {
        for (pa, pb) in a.iter().zip(b) {
            let (pa, pb) = (pa.unwrap(), pb.unwrap());
            let want = [pa[0] * mpu, -pa[2] * mpu, pa[1] * mpu];
            assert!(dist(want, pb) < 1e-5, "{want:?} vs {pb:?}");
        }
    }

    // BVH in place: the skeleton's channels, its root's horizontal path zero.
    let (status, _, body) = srv
        .get(&format!(
            "/v1/sequences/{id}/frames?format=bvh&root=in-place&fps=60"
        ))
        .await;
    assert_eq!(status, 200);
    let back = mocapstore::motion::formats::read(&body, &Default::default()).unwrap();
    assert!((back.motion.fps - 60.0).abs() < 1e-4, "{}", back.motion.fps);
    assert_eq!(back.motion.frame_count(), 497);
    for f in 0..back.motion.frame_count() {
        let r = back.motion.sample(f, 0).unwrap();
        assert!(r[0].abs() < 1e-4 && r[2].abs() < 1e-4, "{r:?}");
    }

    // Refused: a rate that is no rate, root motion of a marker take, glTF in millimetres.
    for q in ["fps=0", "fps=-1", "root=sideways", "up=x", "unit=furlong"] {
        let (status, _, body) = srv.get(&format!("/v1/sequences/{id}/frames?{q}")).await;
        assert_eq!(status, 400, "{q}: {}", String::from_utf8_lossy(&body));
    }
    let (status, _, _) = srv
        .get(&format!("/v1/sequences/{id}/frames?format=glb&unit=mm"))
        .await;
    assert_eq!(status, 400);
    let trc = std::fs::read(root.join("trc/MOTEK__T.trc")).unwrap();
    let (status, report) = srv.post("name=markers", trc).await;
    assert_eq!(status, 201, "{report}");
    let markers = report["id"].as_str().unwrap();
    let (status, _, body) = srv
        .get(&format!("/v1/sequences/{markers}/frames?root=in-place"))
        .await;
    assert_eq!(status, 400, "{}", String::from_utf8_lossy(&body));
    srv.stop().await;
    t.finish().await;
}

/// 30 → 120 → 30 fps through the service: a Bandai take served at 120 fps as BVH, stored
/// again, and served at 30 fps is the take within the bounds of both codings.
#[tokio::test(flavor = "multi_thread")]
async fn up_and_down_again_through_the_service() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let bvh = std::fs::read(root.join("bvh/bandai/dataset-1_bow_active_001.bvh")).unwrap();
    let (status, first) = srv.post("name=bow", bvh).await;
    assert_eq!(status, 201, "{first}");
    let id = first["id"].as_str().unwrap();
    let (_, _, body) = srv.get(&format!("/v1/sequences/{id}/frames")).await;
    let (_, original) = samples(&body);
    let unit = mpu(&body);
    let (status, _, fine) = srv
        .get(&format!("/v1/sequences/{id}/frames?format=bvh&fps=120"))
        .await;
    assert_eq!(status, 200);
    let (status, second) = srv.post("name=bow120", fine).await;
    assert_eq!(status, 201, "{second}");
    assert!(
        (second["fps"].as_f64().unwrap() - 120.0).abs() < 1e-4,
        "{second}"
    );
    let id2 = second["id"].as_str().unwrap();
    let (_, _, body) = srv.get(&format!("/v1/sequences/{id2}/frames?fps=30")).await;
    let (_, back) = samples(&body);
    assert_eq!(back.len(), original.len());
    let tol = measured_max(&first, unit) + measured_max(&second, unit) + 1e-3;
    for (f, (a, b)) in original.iter().zip(&back).enumerate() {
        for (p, (a, b)) in a.iter().zip(b).enumerate() {
            let d = dist(a.unwrap(), b.unwrap());
            assert!(d <= tol, "frame {f} point {p}: {d} > {tol}");
        }
    }
    srv.stop().await;
    t.finish().await;
}

/// The Khronos validator's report of a file: (errors, the first messages).
fn validate(modules: &Path, file: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/gltf/validate.mjs");
    let o = std::process::Command::new("node")
        .arg(script)
        .arg(file)
        .env("GLTF_NODE_MODULES", modules)
        .output()
        .unwrap();
    serde_json::from_slice(o.stdout.trim_ascii()).unwrap_or_else(|_| {
        panic!(
            "validate.mjs said {} {}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    })
}

/// pygltflib's evaluation of a file (scripts/gltf-eval.py).
fn evaluate(python: &Path, file: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/gltf-eval.py");
    let o = std::process::Command::new(python)
        .arg(script)
        .arg(file)
        .output()
        .unwrap();
    serde_json::from_slice(o.stdout.trim_ascii()).unwrap_or_else(|_| {
        panic!(
            "gltf-eval.py said {} {}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    })
}

/// The Node modules of the independent glTF tools, when the tests are given them.
fn node_modules() -> Option<PathBuf> {
    std::env::var_os("MOCAP_TEST_NODE_MODULES").map(PathBuf::from)
}

/// Corpus BVH files, one in `every` (all with `MOCAP_FULL_SWEEP=1`).
fn sampled_bvh(root: &Path, every: usize) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = ["cmu", "bandai", "misc"]
        .iter()
        .flat_map(|d| std::fs::read_dir(root.join("bvh").join(d)).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    files.sort();
    let all = std::env::var("MOCAP_FULL_SWEEP").is_ok_and(|v| v == "1");
    files
        .into_iter()
        .enumerate()
        .filter(|(i, _)| all || i % every == 0)
        .map(|(_, p)| p)
        .collect()
}

/// Every sampled corpus BVH as GLB, a TRC and a C3D marker take as GLB and glTF: the Khronos
/// validator finds no error, and pygltflib's evaluation of the nodes gives the service's
/// own positions (metres, +Y up) within the take's bound.
#[tokio::test(flavor = "multi_thread")]
async fn gltf_reads_back_in_independent_readers() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let python = common::python();
    let modules = node_modules();
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let mut files = sampled_bvh(&root, 12);
    files.push(root.join("trc/MOTEK__T.trc"));
    files.push(root.join("c3d/btkdata__others__Gait.c3d"));
    let dir = std::env::temp_dir().join(format!("mocapstore-gltf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut checked = 0;
    for path in &files {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let (status, report) = srv.post("lenient=true", std::fs::read(path).unwrap()).await;
        assert_eq!(status, 201, "{name}: {report}");
        let id = report["id"].as_str().unwrap().to_string();
        let skeleton = name.ends_with(".bvh");
        let bound_m = report["max_mm"].as_f64().unwrap() * 1e-3;
        let (status, h, glb) = srv
            .get(&format!("/v1/sequences/{id}/frames?format=glb"))
            .await;
        assert_eq!(status, 200, "{name}: {}", String::from_utf8_lossy(&glb));
        assert_eq!(header(&h, "content-type"), "model/gltf-binary");
        let file = dir.join(format!("{name}.glb"));
        std::fs::write(&file, &glb).unwrap();
        if let Some(m) = &modules {
            let v = validate(m, &file);
            assert_eq!(v["errors"], 0, "{name}: {v}");
        }
        if let Some(python) = &python {
            let ev = evaluate(python, &file);
            let (_, _, body) = srv
                .get(&format!("/v1/sequences/{id}/frames?unit=m&up=y"))
                .await;
            let (names, ours) = samples(&body);
            assert_eq!(ev["extras"]["mocapstore"]["id"], id.as_str());
            let nodes: Vec<&str> = ev["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n.as_str().unwrap())
                .collect();
            assert_eq!(nodes, names, "{name}");
            let pos = ev["positions"].as_array().unwrap();
            let vis = ev["visible"].as_array().unwrap();
            assert_eq!(pos.len(), ours.len(), "{name}");
            // The skeleton is evaluated from its channels (f32 quaternions down the
            // chain): within the bound of the decoded positions and a few f32 roundings.
            let tol = if skeleton { bound_m + 1e-4 } else { 1e-6 };
            for (f, (p, o)) in pos.iter().zip(&ours).enumerate() {
                for (n, o) in o.iter().enumerate() {
                    let shown = vis[f][n].as_bool().unwrap();
                    match o {
                        Some(o) => {
                            assert!(shown, "{name} frame {f} node {n} hidden");
                            let q = &p[n];
                            let q = [0, 1, 2].map(|k| q[k].as_f64().unwrap());
                            let d = dist(q, *o);
                            assert!(d <= tol, "{name} frame {f} node {n}: {d} > {tol}");
                        }
                        None => assert!(!shown, "{name} frame {f} node {n} shown in a gap"),
                    }
                }
            }
        }
        checked += 1;
    }
    // The JSON form of a marker take holds the same, embedded.
    let (status, report) = srv
        .post(
            "name=t2",
            std::fs::read(root.join("trc/MOTEK__T.trc")).unwrap(),
        )
        .await;
    assert_eq!(status, 201);
    let id = report["id"].as_str().unwrap();
    let (status, h, gltf) = srv
        .get(&format!("/v1/sequences/{id}/frames?format=gltf&fps=10"))
        .await;
    assert_eq!(status, 200);
    assert_eq!(header(&h, "content-type"), "application/json");
    let doc: Value = serde_json::from_slice(&gltf).unwrap();
    assert!(doc["buffers"][0]["uri"]
        .as_str()
        .unwrap()
        .starts_with("data:application/octet-stream;base64,"));
    if let Some(m) = &modules {
        let file = dir.join("t2.gltf");
        std::fs::write(&file, &gltf).unwrap();
        let v = validate(m, &file);
        assert_eq!(v["errors"], 0, "{v}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    eprintln!("{checked} takes as glTF checked");
    srv.stop().await;
    t.finish().await;
}
