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

/// A BVH with its root's channels set to zero in every frame: what assimp's FBX writer
/// keeps of it (it makes the BVH's root the FBX scene's root, which holds no animation).
fn root_still(bvh: &str) -> String {
    let root_channels: usize = bvh
        .lines()
        .find(|l| l.trim_start().starts_with("CHANNELS"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|n| n.parse().ok())
        .unwrap();
    let mut out = String::new();
    let mut in_motion = false;
    for line in bvh.lines() {
        if in_motion && !line.trim().is_empty() {
            let mut v: Vec<&str> = line.split_whitespace().collect();
            v.iter_mut().take(root_channels).for_each(|x| *x = "0");
            out.push_str(&v.join(" "));
        } else {
            out.push_str(line);
        }
        out.push('\n');
        in_motion |= line.trim_start().starts_with("Frame Time");
    }
    out
}

/// Issue 49: FBX files made from corpus BVH by assimp (Debian's assimp-utils, 5.2), binary
/// (`-ffbx`) and ASCII (`-ffbxa`), read as the BVH says and as assimp reads them back.
///
/// assimp's writer has two faults the comparison allows for, both its own: its binary
/// files leave out the null records that end nested lists (read by their lengths, with a
/// warning), and it writes the BVH's root as the FBX scene's root, whose motion FBX cannot
/// hold (so the reference is the BVH with its root still) and one key per second (so FBX
/// time k s is BVH frame k). Against the BVH: scripts/bvh-fk.py; against assimp's own
/// reading: its GLB of the FBX (`assimp export x.fbx x.glb`), evaluated by pygltflib.
#[tokio::test(flavor = "multi_thread")]
async fn assimp_fbx_of_corpus_bvh_reads_as_the_bvh_and_as_assimp() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    if std::env::var("MOCAP_TEST_ASSIMP").is_err() {
        return;
    }
    let assimp = |args: &[&std::ffi::OsStr]| {
        let o = std::process::Command::new("assimp")
            .args(args)
            .output()
            .expect("MOCAP_TEST_ASSIMP is set: assimp must be installed");
        assert!(o.status.success(), "assimp {args:?}: {o:?}");
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let dir = std::env::temp_dir().join(format!("mocapstore-fbx-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A CMU take (120 fps), a Bandai one (30 fps), a Mixamo rig.
    for source in [
        "bvh/cmu/01_01.bvh",
        "bvh/bandai/dataset-1_walk_active_001.bvh",
        "bvh/misc/mixamo_rig.bvh",
    ] {
        let bvh_path = root.join(source);
        if !bvh_path.exists() {
            panic!("{source} is not in the corpus");
        }
        let text = std::fs::read_to_string(&bvh_path).unwrap();
        let still = dir.join("still.bvh");
        std::fs::write(&still, root_still(&text)).unwrap();
        let reference = common::script(
            &python,
            "bvh-fk.py",
            [still.as_os_str(), "--frames".as_ref(), "0:30".as_ref()],
        );
        let ref_names = common::strings(&reference["names"]);
        for (kind, flag) in [("binary", "-ffbx"), ("ascii", "-ffbxa")] {
            let fbx = dir.join(format!("take-{kind}.fbx"));
            assimp(&[
                "export".as_ref(),
                bvh_path.as_os_str(),
                fbx.as_os_str(),
                flag.as_ref(),
            ]);
            let (status, report) = srv
                .post(&format!("name={kind}"), std::fs::read(&fbx).unwrap())
                .await;
            assert_eq!(status, 201, "{source} {kind}: {report}");
            let id = report["id"].as_str().unwrap();
            let (_, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
            let fps = take["fps"].as_f64().unwrap();
            let unit = take["metres_per_unit"].as_f64().unwrap();
            let bound = take["max_mm"].as_f64().unwrap() * 1e-3 / unit;
            let (status, ours) = srv.get_json(&format!("/v1/takes/{id}/frames")).await;
            assert_eq!(status, 200, "{ours}");
            let names = common::strings(&ours["points"]);
            let frames = ours["frames"].as_array().unwrap();
            // Against the BVH: FBX time k s, BVH frame k; End Sites by their parent.
            let (mut compared, mut worst) = (0usize, 0.0f64);
            for k in 0..reference["frames"].as_u64().unwrap() as usize {
                let f = (k as f64 * fps).round() as usize;
                if f >= frames.len() {
                    break;
                }
                for (i, name) in names.iter().enumerate() {
                    let theirs = match *name {
                        "root" => ref_names[0].to_string(),
                        n => n
                            .strip_prefix("EndSite_")
                            .map_or(n.to_string(), |p| format!("{p}_End")),
                    };
                    let Some(j) = ref_names.iter().position(|n| *n == theirs) else {
                        panic!("{source} {kind}: {name} is not a joint of the BVH");
                    };
                    let a = &frames[f][i];
                    let b = &reference["positions"][k][j];
                    let d = (0..3)
                        .map(|c| (a[c].as_f64().unwrap() - b[c].as_f64().unwrap()).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    worst = worst.max(d);
                    compared += 1;
                }
            }
            // Against assimp's own reading of the same FBX: its ASCII one (assimp cannot
            // read its own binary files back: "block offset is out of range").
            let (mut by_assimp, mut worst_assimp) = (0, 0.0);
            if kind == "ascii" {
                let glb = dir.join("assimp.glb");
                assimp(&[
                    "export".as_ref(),
                    fbx.as_os_str(),
                    glb.as_os_str(),
                    "-fglb2".as_ref(),
                ]);
                let theirs = common::script(&python, "gltf-eval.py", [&glb]);
                let mut renamed = ours.clone();
                if renamed["points"][0] == "root" {
                    renamed["points"][0] = "RootNode".into();
                }
                (by_assimp, worst_assimp) = common::against_gltf_eval(&renamed, &theirs, fps, 0.0);
                assert!(by_assimp >= 3 * names.len(), "{source}: {by_assimp}");
            }
            eprintln!(
                "{source} as {kind} FBX: {} joints, {} frames at {fps} fps, unit {unit} m, up \
                 {}; vs BVH {compared} positions worst {:.4} mm; vs assimp {by_assimp} worst \
                 {:.4} mm (bound {:.3} mm)",
                take["points"],
                take["frames"],
                take["body"]["up"],
                worst * unit * 1e3,
                worst_assimp * unit * 1e3,
                bound * unit * 1e3
            );
            assert!(compared >= 3 * names.len(), "{source} {kind}: {compared}");
            assert!(
                worst <= bound + 1e-6,
                "{source} {kind}: {worst} over {bound}"
            );
            assert!(
                worst_assimp <= bound + 1e-6,
                "{source} {kind}: {worst_assimp} over {bound}"
            );
            if kind == "binary" {
                assert!(
                    report["warnings"].to_string().contains("null record"),
                    "{report}"
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    srv.stop().await;
    t.finish().await;
}

/// `text` (an ASCII FBX) with a second animation stack, "Slow": a copy of the first one
/// (its stack, layer, curve nodes and curves, at new ids, bound to the same nodes) with
/// every key, and the stack's start and stop, at twice its time. What an FBX of several takes (MotionBuilder's, a Mixamo
/// pack's) holds, made from assimp's file of one.
fn with_slow_stack(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let start = lines
        .iter()
        .position(|l| l.starts_with("\tAnimationStack: "))
        .expect("an animation stack");
    let objects_end = start
        + lines[start..]
            .iter()
            .position(|l| *l == "}")
            .expect("the end of Objects");
    // Every object from the stack on is animation (assimp writes them last).
    let id_of = |l: &str| -> Option<u64> {
        let rest = l.strip_prefix('\t')?;
        let (kind, rest) = rest.split_once(": ")?;
        if kind.contains(' ') || kind.contains('\t') {
            return None;
        }
        rest.split_once(',')?.0.parse().ok()
    };
    let ids: std::collections::HashSet<u64> = lines[start..objects_end]
        .iter()
        .filter_map(|l| id_of(l))
        .collect();
    const SHIFT: u64 = 5_000_000;
    let moved = |id: u64| if ids.contains(&id) { id + SHIFT } else { id };
    let mut copy = Vec::new();
    let mut times = false;
    for l in &lines[start..objects_end] {
        times &= !l.trim_start().starts_with('}');
        if let Some(id) = id_of(l) {
            copy.push(
                l.replacen(&id.to_string(), &(id + SHIFT).to_string(), 1)
                    .replace("AnimStack::Motion", "AnimStack::Slow"),
            );
        } else if l.contains("\"KTime\"") {
            // The stack's start and stop: twice as late too.
            let (head, t) = l.rsplit_once(", ").expect("a time");
            copy.push(format!("{head}, {}", 2 * t.trim().parse::<i64>().unwrap()));
        } else if times {
            // The key times: "a: t,t,…" over as many lines as the writer wraps them.
            let (head, keys) = match l.split_once("a: ") {
                Some((indent, keys)) => (format!("{indent}a: "), keys),
                None => (String::new(), *l),
            };
            let doubled: Vec<String> = keys
                .split(',')
                .map(|k| match k.trim() {
                    "" => String::new(),
                    k => (2 * k.parse::<i64>().unwrap()).to_string(),
                })
                .collect();
            copy.push(format!("{head}{}", doubled.join(",")));
        } else {
            copy.push(l.to_string());
        }
        times |= l.trim_start().starts_with("KeyTime: ");
    }
    let mut out: Vec<String> = lines[..objects_end].iter().map(|l| l.to_string()).collect();
    out.extend(copy);
    let connections = objects_end
        + lines[objects_end..]
            .iter()
            .position(|l| l.starts_with("Connections:"))
            .expect("connections");
    out.extend(
        lines[objects_end..=connections]
            .iter()
            .map(|l| l.to_string()),
    );
    for l in &lines[connections + 1..] {
        out.push(l.to_string());
        let Some(rest) = l.trim_start().strip_prefix("C: ") else {
            continue;
        };
        let parts: Vec<&str> = rest.split(", ").collect();
        let (a, b): (u64, u64) = (parts[1].parse().unwrap(), parts[2].parse().unwrap());
        if ids.contains(&a) {
            let mut p = parts.clone();
            let (a, b) = (moved(a).to_string(), moved(b).to_string());
            p[1] = &a;
            p[2] = &b;
            out.push(format!("\tC: {}", p.join(", ")));
        }
    }
    out.join("\n") + "\n"
}

/// An FBX of two animation stacks is two takes, named for their stacks and labelled with
/// them, each read in full; one is picked by `animation=`. The file: assimp's ASCII FBX of
/// a Bandai walk with a second stack at half speed ([`with_slow_stack`]), so frame `2k` of
/// the slow take is frame `k` of the other.
#[tokio::test(flavor = "multi_thread")]
async fn each_animation_stack_of_an_fbx_is_a_take() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    if std::env::var("MOCAP_TEST_ASSIMP").is_err() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("mocapstore-fbx-stacks-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let fbx = dir.join("walk.fbx");
    let o = std::process::Command::new("assimp")
        .arg("export")
        .arg(root.join("bvh/bandai/dataset-1_walk_active_001.bvh"))
        .arg(&fbx)
        .arg("-ffbxa")
        .output()
        .expect("MOCAP_TEST_ASSIMP is set: assimp must be installed");
    assert!(o.status.success(), "{o:?}");
    let file = with_slow_stack(&std::fs::read_to_string(&fbx).unwrap()).into_bytes();
    let _ = std::fs::remove_dir_all(&dir);

    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let (status, report) = srv.post("name=walk&codec=raw", file.clone()).await;
    assert_eq!(status, 201, "{report}");
    assert_eq!(report["name"], "walk/Motion", "{report}");
    let more = report["more"].as_array().expect("the second stack");
    assert_eq!(more.len(), 1, "{report}");
    assert_eq!(more[0]["name"], "walk/Slow", "{report}");
    let mut read = Vec::new();
    for r in [&report, &more[0]] {
        let id = r["id"].as_str().unwrap();
        let (_, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
        assert_eq!(
            take["labels"]["animation"],
            r["name"].as_str().unwrap()[5..]
        );
        let (status, frames) = srv.get_json(&format!("/v1/takes/{id}/frames")).await;
        assert_eq!(status, 200, "{frames}");
        read.push((take, frames));
    }
    let (fast, slow) = (&read[0], &read[1]);
    let n = fast.0["frames"].as_u64().unwrap() as usize;
    assert!(n > 10, "{}", fast.0);
    assert_eq!(slow.0["frames"].as_u64().unwrap() as usize, 2 * n - 1);
    assert_eq!(slow.0["fps"], fast.0["fps"]);
    let worst = (0..n)
        .flat_map(|k| {
            let (a, b) = (&fast.1["frames"][k], &slow.1["frames"][2 * k]);
            let points = a.as_array().unwrap().len();
            (0..points * 3).map(move |i| {
                (a[i / 3][i % 3].as_f64().unwrap() - b[i / 3][i % 3].as_f64().unwrap()).abs()
            })
        })
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-3,
        "the slow stack's frame 2k is the other's k: {worst}"
    );

    let (status, one) = srv.post("name=only&animation=Slow&codec=raw", file).await;
    assert_eq!(status, 201, "{one}");
    assert_eq!(one["name"], "only/Slow");
    assert!(one.get("more").is_none(), "{one}");
    srv.stop().await;
    t.finish().await;
}

/// The metres a unit of take `id` is.
async fn take_unit(srv: &common::Server, id: &str) -> f64 {
    let (_, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
    take["metres_per_unit"].as_f64().unwrap()
}

/// `{"points", "frames"}` of a motion read from a file, in metres: what
/// [`common::against_gltf_eval`] compares with a glTF's evaluation.
fn as_json(m: &mocapstore::motion::Motion) -> serde_json::Value {
    let s = m.unit.metres_per_unit;
    let frames: Vec<Vec<[f64; 3]>> = (0..m.frame_count())
        .map(|f| {
            m.frame(f)
                .chunks_exact(3)
                .map(|p| [p[0], p[1], p[2]].map(|v| f64::from(v) * s))
                .collect()
        })
        .collect();
    serde_json::json!({ "points": m.point_names, "frames": frames })
}

/// Issue 49, FBX out: corpus BVH takes ingested with defaults and given back as binary FBX
/// 7.4 (`format=fbx`: +Y up, the take's unit) read back by our FBX reader (ufbx) and by
/// assimp (its GLB of our FBX, evaluated by pygltflib), and both agree with the GLB of the
/// same take (evaluated by pygltflib) joint for joint, frame for frame; the GLB with the
/// take's own JSON frames; assimp's reading also with the source BVH as an independent
/// reader evaluates it (scripts/bvh-fk.py) within the take's bound. Every CMU and misc BVH of the corpus and every 12th Bandai one
/// (all with `MOCAP_FULL_SWEEP=1`), and a marker take (TRC: null nodes, through assimp).
#[tokio::test(flavor = "multi_thread")]
async fn fbx_out_reads_back_in_ufbx_and_assimp_as_the_glb() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    let with_assimp = std::env::var("MOCAP_TEST_ASSIMP").is_ok();
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let dir = std::env::temp_dir().join(format!("mocapstore-fbx-out-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut files: Vec<std::path::PathBuf> = ["bvh/cmu", "bvh/bandai", "bvh/misc"]
        .iter()
        .flat_map(|d| std::fs::read_dir(root.join(d)).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    files.sort();
    let full = std::env::var("MOCAP_FULL_SWEEP").is_ok_and(|v| v == "1");
    let mut picked: Vec<std::path::PathBuf> = files
        .into_iter()
        .enumerate()
        .filter(|(i, p)| full || i % 12 == 0 || !p.to_string_lossy().contains("/bandai/"))
        .map(|(_, p)| p)
        .collect();
    picked.push(root.join("trc/TRCSamples__Knee.trc"));
    let (mut rows, mut a_skeleton) = (Vec::new(), None);
    // Takes compared with the source BVH's own FK, and the worst as a share of the bound.
    let (mut against_source, mut worst_source) = (0usize, 0f64);
    for path in &picked {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let (status, report) = srv
            .post("name=fbx-out&lenient=true", std::fs::read(path).unwrap())
            .await;
        if status != 201 {
            // A file the service refuses is refused by every output; nothing to compare.
            eprintln!("{name}: not stored ({status}): {report}");
            continue;
        }
        let id = report["id"].as_str().unwrap().to_string();
        let (status, _, fbx) = srv.get(&format!("/v1/takes/{id}/frames?format=fbx")).await;
        assert_eq!(status, 200, "{name}: {}", String::from_utf8_lossy(&fbx));
        let (status, _, glb) = srv.get(&format!("/v1/takes/{id}/frames?format=glb")).await;
        assert_eq!(status, 200, "{name}");
        let glb_path = dir.join("take.glb");
        std::fs::write(&glb_path, &glb).unwrap();
        let by_glb = common::script(&python, "gltf-eval.py", [&glb_path]);
        let fps = report["fps"].as_f64().unwrap();

        // The take's own frames (metres, +Y up), and the GLB of them.
        let (status, frames) = srv
            .get_json(&format!("/v1/takes/{id}/frames?unit=m&up=y"))
            .await;
        assert_eq!(status, 200, "{name}: {frames}");
        let points = frames["points"].as_array().unwrap().len();
        let (n_glb, worst_glb) = common::against_gltf_eval(&frames, &by_glb, fps, 0.0);
        assert!(
            n_glb >= points && worst_glb < 1e-4,
            "{name}: GLB vs the take {worst_glb} m"
        );

        // Ours: the FBX read back (a skeleton take; our reader reads skeletons), in metres.
        let back = mocapstore::motion::formats::read(&fbx, &Default::default());
        let (mut n_ufbx, mut worst_ufbx) = (0, 0.0);
        let unit = take_unit(&srv, &id).await;
        if path.extension().is_some_and(|e| e == "bvh") {
            a_skeleton = Some(id.clone());
            let back = back.unwrap_or_else(|e| panic!("{name}: our FBX does not read back: {e}"));
            assert_eq!(
                back.motion.frame_count(),
                report["frames"].as_u64().unwrap() as usize
            );
            let read_unit = back.motion.unit.metres_per_unit;
            assert!(
                (read_unit - unit).abs() < 1e-9 * unit,
                "{name}: {read_unit} m a unit"
            );
            let ours = as_json(&back.motion);
            (n_ufbx, worst_ufbx) = common::against_gltf_eval(&ours, &by_glb, fps, 0.0);
            assert!(n_ufbx >= back.motion.point_count(), "{name}: {n_ufbx}");
            assert!(worst_ufbx < 1e-4, "{name}: ufbx vs the GLB {worst_ufbx} m");
        }

        // assimp's reading of the same FBX (skeleton or markers), against the GLB.
        let (mut n_assimp, mut worst_assimp) = (0, 0.0);
        if with_assimp {
            let fbx_path = dir.join("take.fbx");
            std::fs::write(&fbx_path, &fbx).unwrap();
            let out = dir.join("assimp.glb");
            let o = std::process::Command::new("assimp")
                .args([
                    "export".as_ref(),
                    fbx_path.as_os_str(),
                    out.as_os_str(),
                    "-fglb2".as_ref(),
                ])
                .output()
                .expect("MOCAP_TEST_ASSIMP is set: assimp must be installed");
            assert!(o.status.success(), "{name}: assimp: {o:?}");
            let by_assimp = common::script(&python, "gltf-eval.py", [&out]);
            // assimp keeps the file's unit: the take's frames in its units.
            let mut in_units = frames.clone();
            for f in in_units["frames"].as_array_mut().unwrap() {
                for p in f.as_array_mut().unwrap() {
                    for c in p.as_array_mut().into_iter().flatten() {
                        if let Some(v) = c.as_f64() {
                            *c = (v / unit).into();
                        }
                    }
                }
            }
            (n_assimp, worst_assimp) = common::against_gltf_eval(&in_units, &by_assimp, fps, 0.0);
            worst_assimp *= unit;
            assert!(n_assimp >= points, "{name}: {n_assimp}");
            assert!(
                worst_assimp < 1e-4,
                "{name}: assimp vs the take {worst_assimp} m"
            );
            // And against the source itself, read by an independent BVH reader
            // (scripts/bvh-fk.py, file units and axes): a +Y-up body's FBX is the file's
            // axes and units, within the take's bound.
            if path.extension().is_some_and(|e| e == "bvh") {
                let (_, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
                if take["body"]["up"] == "y" {
                    let fk = common::script(
                        &python,
                        "bvh-fk.py",
                        [path.as_os_str(), "--frames".as_ref(), "0:60".as_ref()],
                    );
                    let source = serde_json::json!({
                        "points": fk["names"],
                        "frames": fk["positions"],
                    });
                    let (n, worst) = common::against_gltf_eval(&source, &by_assimp, fps, 0.0);
                    let bound = take["max_mm"].as_f64().unwrap() * 1e-3 / unit;
                    assert!(n >= points, "{name}: {n} against the source");
                    assert!(
                        worst <= bound * 1.0001 + 1e-6,
                        "{name}: assimp's reading of our FBX is {worst} from the BVH's FK, over \
                         the bound {bound} (file units)"
                    );
                    against_source += 1;
                    if bound > 0.0 {
                        worst_source = worst_source.max(worst / bound);
                    }
                }
            }
        }
        rows.push(format!(
            "{name}: {points} points × {} frames at {fps} fps, codec {}; ufbx vs GLB {n_ufbx} \
             positions worst {:.4} mm; assimp vs the take {n_assimp} worst {:.4} mm; GLB vs the \
             take worst {:.4} mm",
            report["frames"],
            report["codec"],
            worst_ufbx * 1e3,
            worst_assimp * 1e3,
            worst_glb * 1e3
        ));
    }
    for r in &rows {
        eprintln!("{r}");
    }
    assert!(rows.len() >= 10, "{} takes compared", rows.len());
    eprintln!(
        "{against_source} takes against the source BVH's FK: worst {worst_source:.3} of the bound"
    );
    if with_assimp {
        assert!(
            against_source >= 10,
            "{against_source} takes against the source"
        );
    }
    // Another unit and up, as asked; an up FBX does not state is a 400; a library export.
    let id = a_skeleton.unwrap();
    let (status, _, fbx) = srv
        .get(&format!("/v1/takes/{id}/frames?format=fbx&unit=m&up=z"))
        .await;
    assert_eq!(status, 200);
    let back = mocapstore::motion::formats::read(&fbx, &Default::default()).unwrap();
    assert_eq!(back.motion.unit.metres_per_unit, 1.0);
    let (status, _, body) = srv
        .get(&format!("/v1/takes/{id}/frames?format=fbx&up=x"))
        .await;
    assert_eq!(status, 400, "{}", String::from_utf8_lossy(&body));
    let (status, _, zip) = srv.get("/v1/export?format=fbx").await;
    assert_eq!(status, 200);
    let entries = zip.windows(4).filter(|w| w == b".fbx").count();
    assert!(entries >= rows.len(), "{entries} FBX files in the export");
    let _ = std::fs::remove_dir_all(&dir);
    srv.stop().await;
    t.finish().await;
}
