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

/// The corpus file `rel` stored with `query`: its id and ingest report.
async fn ingest(srv: &common::Server, root: &Path, rel: &str, query: &str) -> (String, Value) {
    let (status, report) = srv
        .post(query, std::fs::read(root.join(rel)).unwrap())
        .await;
    assert_eq!(status, 201, "{rel}: {report}");
    (report["id"].as_str().unwrap().to_string(), report)
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
    let (id, report) = ingest(&srv, &root, "bvh/cmu/131_01.bvh", "name=cmu").await;
    let (status, _, body) = srv.get(&format!("/v1/takes/{id}/frames")).await;
    assert_eq!(status, 200);
    let (names, full) = samples(&body);
    let mpu = mpu(&body);
    let bound = measured_max(&report, mpu);
    assert_eq!(full.len(), 994);

    // 120 → 30 fps: every fourth frame of the full-rate decode.
    let (status, h, body) = srv.get(&format!("/v1/takes/{id}/frames?fps=30")).await;
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
        .get(&format!("/v1/takes/{id}/frames?fps=30&start=400&end=600"))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let (_, part) = samples(&body);
    assert_eq!(part.len(), 50);
    assert_eq!(part[0], quarter[100]);

    // In place: the root's horizontal path is zero, its height and every point relative to
    // it unchanged (f32 answers: within a few ulps of centimetres).
    let (status, _, body) = srv
        .get(&format!("/v1/takes/{id}/frames?root=in-place"))
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
            "/v1/takes/{id}/frames?root=extract&points=Hips,LeftWrist"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let (named, extract) = samples(&body);
    assert_eq!(
        named,
        ["Hips", "LeftWrist", "root_motion", "root_motion_forward"]
    );
    let hand = names.iter().position(|n| n == "LeftWrist").unwrap();
    // The path runs on the body's floor, under the lowest foot point.
    let (_, _, record) = srv.get(&format!("/v1/takes/{id}")).await;
    let record: Value = serde_json::from_slice(&record).unwrap();
    let floor = record["body"]["floor_m"].as_f64().unwrap() / mpu;
    let lowest = full
        .iter()
        .flatten()
        .map(|p| p.unwrap()[1])
        .fold(f64::MAX, f64::min);
    assert!(
        floor >= lowest && floor < lowest + 3.0,
        "{floor} vs {lowest}"
    );
    // The heading apart: the body turned to face its forward, the heading as a point half
    // a metre ahead of the path; turned back and carried along the path, it is the take.
    let forward = match record["body"]["forward"].as_str().unwrap() {
        "x" => [1.0, 0.0],
        "-x" => [-1.0, 0.0],
        "z" => [0.0, 1.0],
        "-z" => [0.0, -1.0],
        other => panic!("forward {other}"),
    };
    for (f, e) in extract.iter().enumerate() {
        let (hips, path, ahead) = (e[0].unwrap(), e[2].unwrap(), e[3].unwrap());
        assert!((path[1] - floor).abs() < 1e-4, "{path:?}");
        assert!((ahead[1] - floor).abs() < 1e-4, "{ahead:?}");
        let d = [ahead[0] - path[0], ahead[2] - path[2]];
        assert!(((d[0].hypot(d[1])) * mpu - 0.5).abs() < 1e-6, "{d:?}");
        // The turn about +Y that takes forward (x, z) to d: x' = x cos + z sin, z' = −x sin + z cos.
        let angle =
            (forward[1] * d[0] - forward[0] * d[1]).atan2(forward[0] * d[0] + forward[1] * d[1]);
        let (sin, cos) = angle.sin_cos();
        let world = |p: [f64; 3]| {
            [
                p[0] * cos + p[2] * sin + path[0],
                p[1],
                -p[0] * sin + p[2] * cos + path[2],
            ]
        };
        let original = full[f][0].unwrap();
        assert!(dist(world(hips), original) < 1e-3, "frame {f}");
        let h = full[f][hand].unwrap();
        assert!(dist(world(e[1].unwrap()), h) < 1e-3, "frame {f}");
    }

    // Z up, in metres: (x, y, z) cm → (x, −z, y) / 100.
    let (status, h, body) = srv
        .get(&format!("/v1/takes/{id}/frames?up=z&unit=m&end=50"))
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
            "/v1/takes/{id}/frames?format=bvh&root=in-place&fps=60"
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

    // Refused: a rate that is no rate, an axis that is none, glTF in millimetres.
    for q in [
        "fps=0",
        "fps=-1",
        "fps=0.001",
        "fps=1e-310",
        "root=sideways",
        "up=w",
        "unit=furlong",
        "format=c3d&up=z",
    ] {
        let (status, _, body) = srv.get(&format!("/v1/takes/{id}/frames?{q}")).await;
        assert_eq!(status, 400, "{q}: {}", String::from_utf8_lossy(&body));
    }
    let (status, _, _) = srv
        .get(&format!("/v1/takes/{id}/frames?format=glb&unit=mm"))
        .await;
    assert_eq!(status, 400);
    // A marker take's root motion follows its pelvis markers' centroid.
    let (markers, _) = ingest(&srv, &root, "trc/MOTEK__T.trc", "name=markers").await;
    let pelvis = "LFWT,RFWT,LBWT,RBWT";
    let (status, _, body) = srv
        .get(&format!(
            "/v1/takes/{markers}/frames?root=in-place&points={pelvis}"
        ))
        .await;
    assert_eq!(
        status,
        200,
        "{}",
        String::from_utf8_lossy(&body[..body.len().min(300)])
    );
    let (_, inplace) = samples(&body);
    for f in &inplace {
        let c: Vec<[f64; 3]> = f.iter().flatten().copied().collect();
        let mean = |a: usize| c.iter().map(|p| p[a]).sum::<f64>() / c.len() as f64;
        // MOTEK's TRC is Y-up: x and z are the ground.
        assert!(mean(0).abs() < 1e-3 && mean(2).abs() < 1e-3, "{c:?}");
    }
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
    let (id, first) = ingest(
        &srv,
        &root,
        "bvh/bandai/dataset-1_bow_active_001.bvh",
        "name=bow",
    )
    .await;
    let (_, _, body) = srv.get(&format!("/v1/takes/{id}/frames")).await;
    let (_, original) = samples(&body);
    let unit = mpu(&body);
    let (status, _, fine) = srv
        .get(&format!("/v1/takes/{id}/frames?format=bvh&fps=120"))
        .await;
    assert_eq!(status, 200);
    let (status, second) = srv.post("name=bow120", fine).await;
    assert_eq!(status, 201, "{second}");
    assert!(
        (second["fps"].as_f64().unwrap() - 120.0).abs() < 1e-4,
        "{second}"
    );
    let id2 = second["id"].as_str().unwrap();
    let (_, _, body) = srv.get(&format!("/v1/takes/{id2}/frames?fps=30")).await;
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

/// pygltflib's evaluation of a file (scripts/gltf-eval.py).
fn evaluate(python: &Path, file: &Path) -> Value {
    common::script(python, "gltf-eval.py", [file])
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
    let modules = common::node_modules();
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
        let (status, h, glb) = srv.get(&format!("/v1/takes/{id}/frames?format=glb")).await;
        assert_eq!(status, 200, "{name}: {}", String::from_utf8_lossy(&glb));
        assert_eq!(header(&h, "content-type"), "model/gltf-binary");
        let file = dir.join(format!("{name}.glb"));
        std::fs::write(&file, &glb).unwrap();
        if let Some(m) = &modules {
            let v = common::validate(m, &file);
            assert_eq!(v["errors"], 0, "{name}: {v}");
        }
        if let Some(python) = &python {
            let ev = evaluate(python, &file);
            let (_, _, body) = srv.get(&format!("/v1/takes/{id}/frames?unit=m&up=y")).await;
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
        .get(&format!("/v1/takes/{id}/frames?format=gltf&fps=10"))
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
        let v = common::validate(m, &file);
        assert_eq!(v["errors"], 0, "{v}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    eprintln!("{checked} takes as glTF checked");
    srv.stop().await;
    t.finish().await;
}

/// py-c3d's and ezc3d's reading of a C3D we wrote against our JSON answer of the same take
/// (scripts/c3d-check.py).
fn check_c3d(python: &Path, c3d: &[u8], json: &[u8], tol: f64, tag: &str) -> Value {
    let dir = std::env::temp_dir();
    let stem = format!("mocapstore-c3dout-{}-{tag}", std::process::id());
    let (c, j) = (
        dir.join(format!("{stem}.c3d")),
        dir.join(format!("{stem}.json")),
    );
    std::fs::write(&c, c3d).unwrap();
    std::fs::write(&j, json).unwrap();
    let tol = tol.to_string();
    let args = [c.as_os_str(), j.as_os_str(), "--tol".as_ref(), tol.as_ref()];
    let v = common::script(python, "c3d-check.py", args);
    let _ = (std::fs::remove_file(&c), std::fs::remove_file(&j));
    v
}

/// C3D out of every kind of take, through the one read path: every corpus TRC, BVH takes
/// (joints and End Sites as points) and a C3D resampled with its analog channels: py-c3d
/// and ezc3d read the labels, rate, frame count and positions of our own JSON answer of
/// the same request, and missing samples where it has none.
#[tokio::test(flavor = "multi_thread")]
async fn c3d_out_of_every_kind_of_take() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let mut cases: Vec<(PathBuf, &str)> = std::fs::read_dir(root.join("trc"))
        .unwrap()
        .map(|e| (e.unwrap().path(), ""))
        .collect();
    cases.sort();
    cases.push((root.join("bvh/cmu/131_01.bvh"), "&end=300"));
    cases.push((root.join("bvh/misc/vicon.bvh"), "&fps=60"));
    cases.push((root.join("c3d/btkdata__others__Gait.c3d"), "&fps=50"));
    let mut checked = 0;
    for (path, query) in &cases {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let (status, report) = srv.post("lenient=true", std::fs::read(path).unwrap()).await;
        if status != 201 {
            // A corpus file our reader refuses (an empty TRC): nothing to write back.
            assert!(status == 422 || status == 400, "{name}: {status} {report}");
            eprintln!("{name}: not stored ({report})");
            continue;
        }
        let id = report["id"].as_str().unwrap().to_string();
        let (status, _, c3d) = srv
            .get(&format!("/v1/takes/{id}/frames?format=c3d{query}"))
            .await;
        assert_eq!(status, 200, "{name}: {}", String::from_utf8_lossy(&c3d));
        let (status, _, json) = srv
            .get(&format!("/v1/takes/{id}/frames?format=json{query}"))
            .await;
        assert_eq!(status, 200, "{name}");
        // Both hold the same f32 values (the C3D's in mm where the take's unit has no C3D
        // name): within an f32's rounding of a few metres.
        let v = check_c3d(&python, &c3d, &json, 1e-5, &checked.to_string());
        assert_eq!(v["ok"], true, "{name}{query}: {v}");
        checked += 1;
    }
    assert!(checked >= 10, "{checked}");
    srv.stop().await;
    t.finish().await;
}

/// `mocapstore convert` takes the same transforms: a CMU take to GLB at 30 fps in place
/// (pygltflib's evaluation: 249 frames, the root's horizontal path zero), a C3D with force
/// plates to C3D at half its rate (the analog channels keep theirs: twice the samples a
/// frame), and a clear error for a rate its analog cannot divide into.
#[test]
fn convert_takes_the_same_transforms() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("mocapstore-convert-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let glb = dir.join("walk.glb");
    let bvh = root.join("bvh/cmu/131_01.bvh");
    let (ok, _, err) = common::mocapstore(&[
        "convert",
        bvh.to_str().unwrap(),
        glb.to_str().unwrap(),
        "--out-fps",
        "30",
        "--root",
        "in-place",
    ]);
    assert!(ok, "{err}");
    if let Some(python) = common::python() {
        let ev = evaluate(&python, &glb);
        assert_eq!(ev["frames"], 249);
        for f in ev["positions"].as_array().unwrap() {
            let hips = f[0].as_array().unwrap();
            assert!(hips[0].as_f64().unwrap().abs() < 1e-6, "{hips:?}");
            assert!(hips[2].as_f64().unwrap().abs() < 1e-6, "{hips:?}");
        }
    }
    if let Some(m) = common::node_modules() {
        assert_eq!(common::validate(&m, &glb)["errors"], 0);
    }
    let gait = root.join("c3d/btkdata__others__Gait.c3d");
    let source =
        mocapstore::motion::formats::read(&std::fs::read(&gait).unwrap(), &Default::default())
            .unwrap();
    let half = source.motion.fps / 2.0;
    let out = dir.join("gait.c3d");
    let (ok, _, err) = common::mocapstore(&[
        "convert",
        gait.to_str().unwrap(),
        out.to_str().unwrap(),
        "--out-fps",
        &half.to_string(),
    ]);
    assert!(ok, "{err}");
    let back =
        mocapstore::motion::formats::read(&std::fs::read(&out).unwrap(), &Default::default())
            .unwrap();
    assert_eq!(back.motion.fps, half);
    let (a, b) = (
        source.extras.analog.as_ref().unwrap(),
        back.extras.analog.as_ref().unwrap(),
    );
    assert_eq!(b.per_frame, a.per_frame * 2);
    assert_eq!(b.frames(), back.motion.frame_count());
    let (ok, _, err) = common::mocapstore(&[
        "convert",
        gait.to_str().unwrap(),
        out.to_str().unwrap(),
        "--out-fps",
        "7",
    ]);
    assert!(
        !ok && err.contains("not a whole number of samples"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `assimp info` (Debian's assimp-utils; `.ci/run` installs it and sets
/// `MOCAP_TEST_ASSIMP=1`) opens the GLB and the BVH the service writes of a skeleton take,
/// resampled and in place, and finds its nodes and one animation.
#[tokio::test(flavor = "multi_thread")]
async fn assimp_opens_the_glb_and_bvh_exports() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    if std::env::var("MOCAP_TEST_ASSIMP").is_err() {
        return;
    }
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let (id, _) = ingest(&srv, &root, "bvh/cmu/131_01.bvh", "name=cmu").await;
    let dir = std::env::temp_dir().join(format!("mocapstore-assimp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for format in ["glb", "bvh"] {
        let (status, _, body) = srv
            .get(&format!(
                "/v1/takes/{id}/frames?format={format}&fps=30&root=in-place"
            ))
            .await;
        assert_eq!(status, 200, "{format}");
        let file = dir.join(format!("take.{format}"));
        std::fs::write(&file, &body).unwrap();
        let o = std::process::Command::new("assimp")
            .arg("info")
            .arg(&file)
            .output()
            .expect("MOCAP_TEST_ASSIMP is set: assimp must be installed");
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "assimp info {format}: {text} {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let count = |what: &str| {
            text.lines()
                .find(|l| l.trim_start().starts_with(what))
                .and_then(|l| l.split(':').nth(1))
                .and_then(|v| v.trim().parse::<u64>().ok())
                .unwrap_or_else(|| panic!("{format}: no {what:?} in {text}"))
        };
        assert_eq!(count("Animations"), 1, "{format}: {text}");
        assert!(count("Nodes") >= 31, "{format}: {text}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    srv.stop().await;
    t.finish().await;
}

/// A take of analog channels and no points still has frames: resampled, its answers count
/// them (x-frames and the body agree).
#[tokio::test(flavor = "multi_thread")]
async fn a_take_of_no_points_resamples_its_frames() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let (id, report) = ingest(&srv, &root, "c3d/c3dio__sample_30__emgwl.c3d", "name=emg").await;
    assert_eq!(report["points"], 0, "{report}");
    let frames = report["frames"].as_u64().unwrap();
    let fps = report["fps"].as_f64().unwrap();
    let (status, h, body) = srv
        .get(&format!("/v1/takes/{id}/frames?fps={}", fps / 2.0))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let out: usize = header(&h, "x-frames").parse().unwrap();
    assert_eq!(out as u64, frames.div_ceil(2));
    let (_, got) = samples(&body);
    assert_eq!(got.len(), out);
    srv.stop().await;
    t.finish().await;
}

/// NPY, CSV and f32 answers with transforms, read by numpy (`np.load`, `np.genfromtxt`,
/// `np.fromfile` with the shape headers), hold the JSON answer's samples and gaps: a marker
/// take with gaps at 30 fps, +Z up, in metres, and a skeleton take in place at 60 fps.
#[tokio::test(flavor = "multi_thread")]
async fn numpy_reads_the_position_formats_with_transforms() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let (markers, _) = ingest(&srv, &root, "trc/TRCSamples__Gait.trc", "name=gait").await;
    let (skeleton, _) = ingest(&srv, &root, "bvh/cmu/131_01.bvh", "name=cmu").await;
    let dir = std::env::temp_dir().join(format!("mocapstore-numpy-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (id, query) in [
        (&markers, "fps=30&up=z&unit=m"),
        (&skeleton, "fps=60&root=in-place&unit=cm"),
    ] {
        let mut paths = Vec::new();
        let mut shape = (0, 0);
        for format in ["json", "npy", "csv", "f32"] {
            let (status, h, body) = srv
                .get(&format!("/v1/takes/{id}/frames?format={format}&{query}"))
                .await;
            assert_eq!(status, 200, "{format} {query}");
            if format == "f32" {
                shape = (
                    header(&h, "x-frames").parse::<usize>().unwrap(),
                    header(&h, "x-points").parse::<usize>().unwrap(),
                );
            }
            let p = dir.join(format!("take.{format}"));
            std::fs::write(&p, &body).unwrap();
            paths.push(p);
        }
        let script = r#"
import json, sys, numpy as np
j, npy, csv, f32, frames, points = sys.argv[1:7]
frames, points = int(frames), int(points)
doc = json.load(open(j))
ref = np.array([[p if p is not None else [np.nan] * 3 for p in f] for f in doc["frames"]],
               dtype=np.float64).reshape(len(doc["frames"]), -1, 3)
got = {
    "npy": np.load(npy).astype(np.float64),
    "csv": np.genfromtxt(csv, delimiter=",", skip_header=1)[:, 2:].reshape(ref.shape[0], -1, 3),
    "f32": np.fromfile(f32, dtype="<f4").astype(np.float64).reshape(frames, points, 3),
}
out = {"shape": list(ref.shape), "gaps": int(np.isnan(ref).sum())}
for k, v in got.items():
    assert v.shape == ref.shape, (k, v.shape, ref.shape)
    assert (np.isnan(v) == np.isnan(ref)).all(), k
    ok = ~np.isnan(ref)
    out[k] = float(np.abs(v[ok] - ref[ok]).max() / max(1.0, np.abs(ref[ok]).max()))
print(json.dumps(out))
"#;
        let o = std::process::Command::new(&python)
            .arg("-c")
            .arg(script)
            .args(&paths)
            .arg(shape.0.to_string())
            .arg(shape.1.to_string())
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{query}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        // f32 values printed as text read back within an f32's rounding.
        for k in ["npy", "csv", "f32"] {
            assert!(v[k].as_f64().unwrap() < 1e-6, "{query}: {v}");
        }
        assert_eq!(v["shape"][0].as_u64().unwrap() as usize, shape.0, "{v}");
        eprintln!("{query}: {v}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    srv.stop().await;
    t.finish().await;
}
