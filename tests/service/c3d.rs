//! C3D kept whole (issue 34): every corpus C3D with analog channels goes in with defaults
//! and comes back — its analog channels through `GET …/analog`, the file through
//! `frames?format=c3d` — and the returned file reads in py-c3d and ezc3d like the upload
//! (`scripts/c3d-compare.py`): point labels, values within the bound, analog values
//! identical, labels, rates, scales, offsets, units, events and FORCE_PLATFORM.

use crate::common;

use std::path::{Path, PathBuf};

use mocapstore::corpus;
use mocapstore::motion::formats::{self, ReadOptions};
use serde_json::Value;

/// Files the independent readers misread, where the comparison with them cannot hold: the
/// file, and why.
const MISREAD: &[(&str, &str)] = &[(
    "c3dio__sample_11__evart.c3d",
    "its header holds 17 analog samples a frame (476 words) and ANALOG:RATE 1000 at 60 fps; \
     ezc3d reads 16 a frame and misaligns every frame after the first, py-c3d refuses it",
)];

/// Corpus C3D files with analog channels, as our reader reads them (lenient: a few are
/// truncated), in name order.
fn analog_files(root: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(root.join("c3d"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "c3d"))
        .collect();
    files.sort();
    let lenient = ReadOptions {
        lenient: true,
        ..ReadOptions::default()
    };
    files
        .into_iter()
        .filter(|p| {
            formats::read(&std::fs::read(p).unwrap(), &lenient)
                .is_ok_and(|l| l.extras.analog.is_some())
        })
        .collect()
}

/// One file in five by default (each run the same fifth: 16 files, a minute of CPU), all
/// with `MOCAP_FULL_SWEEP=1`: a file costs an ingest with every codec competing, two reads
/// and two Python readers.
fn sampled(i: usize) -> bool {
    std::env::var("MOCAP_FULL_SWEEP").is_ok_and(|v| v == "1") || i.is_multiple_of(5)
}

fn compare(python: &Path, original: &Path, returned: &[u8], extra: &[String]) -> Value {
    let out = std::env::temp_dir().join(format!(
        "mocapstore-c3d-{}-{}.c3d",
        std::process::id(),
        original.file_stem().unwrap().to_string_lossy()
    ));
    std::fs::write(&out, returned).unwrap();
    let mut args: Vec<std::ffi::OsString> = vec![original.into(), out.clone().into()];
    args.extend(extra.iter().map(Into::into));
    let v = common::script(python, "c3d-compare.py", args);
    let _ = std::fs::remove_file(&out);
    v
}

#[tokio::test(flavor = "multi_thread")]
async fn c3d_files_come_back_whole() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let python = common::python();
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let files = analog_files(&root);
    assert!(
        files.len() >= 70,
        "{} corpus files with analog",
        files.len()
    );
    let mut checked = 0;
    for (_, path) in files.iter().enumerate().filter(|(i, _)| sampled(*i)) {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let bytes = std::fs::read(path).unwrap();
        let (status, report) = srv.post("lenient=true", bytes.clone()).await;
        assert_eq!(status, 201, "{name}: {report}");
        let id = report["id"].as_str().unwrap().to_string();
        let analog = &report["analog"];
        assert_eq!(analog["codec"], "analog-lossless", "{name}: {report}");
        // Honest sizes: raw counts the analog values as the file held them.
        let ours = formats::read(
            &bytes,
            &ReadOptions {
                lenient: true,
                ..ReadOptions::default()
            },
        )
        .unwrap();
        let a = ours.extras.analog.as_ref().unwrap();
        assert_eq!(analog["raw_bytes"], a.raw_bytes() as u64, "{name}");
        let points_raw = ours.motion.frame_count() * ours.motion.point_count() * 12;
        let outputs_raw = ours
            .extras
            .outputs
            .as_ref()
            .map_or(0, |o| o.values.len() * 4);
        assert_eq!(
            report["raw_bytes"],
            (points_raw + a.raw_bytes() + outputs_raw) as u64,
            "{name}"
        );

        // The whole analog answer is every value in its unit, as the file holds it.
        let (status, _, body) = srv.get(&format!("/v1/takes/{id}/analog?format=json")).await;
        assert_eq!(status, 200, "{name}");
        let whole: Value = serde_json::from_slice(&body).unwrap();
        let rows = whole["values"].as_array().unwrap();
        assert_eq!(rows.len(), a.rows(), "{name}");
        for (r, row) in rows.iter().enumerate().step_by(7) {
            for (c, v) in row.as_array().unwrap().iter().enumerate() {
                let want = a.value(r, c);
                match v.as_f64() {
                    Some(v) => assert_eq!(v, want, "{name} row {r} channel {c}"),
                    None => assert!(!want.is_finite(), "{name} row {r} channel {c}"),
                }
            }
        }
        // A range read is the same rows of the whole decode.
        let frames = ours.motion.frame_count();
        if frames > 4 {
            let (s, e) = (frames / 3, frames / 3 + frames / 4 + 1);
            let (status, _, body) = srv
                .get(&format!(
                    "/v1/takes/{id}/analog?format=json&start={s}&end={e}"
                ))
                .await;
            assert_eq!(status, 200, "{name}");
            let part: Value = serde_json::from_slice(&body).unwrap();
            let per = a.per_frame;
            assert_eq!(
                part["values"].as_array().unwrap().as_slice(),
                &rows[s * per..e * per],
                "{name}"
            );
        }

        // The file back, read by the independent readers.
        let (status, _, c3d) = srv.get(&format!("/v1/takes/{id}/frames?format=c3d")).await;
        assert_eq!(status, 200, "{name}");
        if let Some(python) = &python {
            let bound_mm = report["decision"]["tried"]
                .as_array()
                .unwrap()
                .iter()
                .find(|t| t["codec"] == report["codec"])
                .and_then(|t| t["max_mm"].as_f64())
                .unwrap();
            let mpu = ours.motion.unit.metres_per_unit;
            // Within what was measured (in the file's units), and f32 rounding.
            let tol = bound_mm * 1e-3 / mpu * 1.0001 + 1e-3;
            let v = compare(python, path, &c3d, &["--point-tol".into(), tol.to_string()]);
            let misread = MISREAD.iter().any(|(f, _)| *f == name);
            if v["ok"] != true && !misread {
                panic!("{name}: {v}");
            }
        }
        checked += 1;
    }
    eprintln!("{checked} of {} C3D files with analog checked", files.len());
    assert!(checked >= files.len() / 5, "{checked}");
    srv.stop().await;
    t.finish().await;
}

#[tokio::test(flavor = "multi_thread")]
async fn analog_bounds_and_analog_only_files() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;

    // An EMG-only file: a take of channels and no points.
    let emg = std::fs::read(root.join("c3d/c3dio__sample_30__emgwl.c3d")).unwrap();
    let (status, report) = srv.post("name=emg", emg.clone()).await;
    assert_eq!(status, 201, "{report}");
    assert_eq!(
        (report["points"].as_u64(), report["frames"].as_u64()),
        (Some(0), Some(501))
    );
    let id = report["id"].as_str().unwrap().to_string();
    let (status, _, body) = srv
        .get(&format!("/v1/takes/{id}/analog?format=csv&channels=MG-2"))
        .await;
    let text = String::from_utf8(body).unwrap();
    assert_eq!(status, 200, "{text}");
    assert!(
        text.lines().count() > 1000,
        "{}",
        &text[..200.min(text.len())]
    );
    let (status, _, c3d) = srv.get(&format!("/v1/takes/{id}/frames?format=c3d")).await;
    assert_eq!(status, 200);
    let back = formats::read(&c3d, &ReadOptions::default()).unwrap();
    assert_eq!(back.motion.point_count(), 0);
    assert_eq!(back.extras.analog.unwrap().rows(), 16032);

    // Bounded: every channel within its bound in its own unit, and smaller.
    let fp = std::fs::read(root.join("c3d/btkdata__PiG__PiG_Motion-FlatFoot-Full.c3d")).unwrap();
    let (_, exact) = srv.post("name=exact", fp.clone()).await;
    let (status, bounded) = srv
        .post("name=bounded&analog_bound=*=0.001,Fz1=0.5", fp.clone())
        .await;
    assert_eq!(status, 201, "{bounded}");
    let a = &bounded["analog"];
    assert_eq!(a["codec"], "analog-bounded", "{a}");
    assert!(
        a["stored_bytes"].as_u64() < exact["analog"]["stored_bytes"].as_u64(),
        "{a}"
    );
    for ch in a["channels"].as_array().unwrap() {
        let bound = if ch["label"] == "Fz1" { 0.5 } else { 0.001 };
        assert_eq!(ch["bound"].as_f64(), Some(bound), "{ch}");
        assert!(ch["max_error"].as_f64().unwrap() <= bound, "{ch}");
    }
    let ours = formats::read(&fp, &ReadOptions::default())
        .unwrap()
        .extras
        .analog
        .unwrap();
    let id = bounded["id"].as_str().unwrap();
    let (_, _, body) = srv.get(&format!("/v1/takes/{id}/analog?format=json")).await;
    let v: Value = serde_json::from_slice(&body).unwrap();
    for (r, row) in v["values"].as_array().unwrap().iter().enumerate() {
        for (c, x) in row.as_array().unwrap().iter().enumerate() {
            let bound = if ours.channels[c].label == "Fz1" {
                0.5
            } else {
                0.001
            };
            assert!(
                (x.as_f64().unwrap() - ours.value(r, c)).abs() <= bound,
                "{r} {c}"
            );
        }
    }

    // Bad requests: a label the take lacks, a bound that is not one, analog codecs for
    // points, analog of a take without any.
    for (query, want) in [
        ("codec=quant&analog_bound=NoSuch=1", "NoSuch"),
        ("analog_bound=-1", "positive"),
        ("codec=analog-lossless", "analog channels"),
    ] {
        let (status, body) = srv.post(query, fp.clone()).await;
        assert_eq!(status, 400, "{query}: {body}");
        assert!(
            body["error"]["message"].as_str().unwrap().contains(want),
            "{body}"
        );
    }
    let trc = std::fs::read(root.join("trc/TRCSamples__Knee.trc")).unwrap();
    let (_, knee) = srv.post("name=knee&codec=quant", trc).await;
    let id = knee["id"].as_str().unwrap();
    let (status, _, _) = srv.get(&format!("/v1/takes/{id}/analog")).await;
    assert_eq!(status, 409);
    let (status, _, _) = srv.get(&format!("/v1/takes/{id}/parameters")).await;
    assert_eq!(status, 409);

    // Parameters and events are kept and shown.
    let (status, view) = srv
        .get_json(&format!("/v1/takes/{}", exact["id"].as_str().unwrap()))
        .await;
    assert_eq!(status, 200);
    assert_eq!(
        view["meta"]["events"].as_array().map(Vec::len),
        Some(12),
        "{}",
        view["meta"]
    );
    let (status, p) = srv
        .get_json(&format!(
            "/v1/takes/{}/parameters",
            exact["id"].as_str().unwrap()
        ))
        .await;
    assert_eq!(status, 200, "{p}");
    assert_eq!(
        p["force_platforms"].as_array().map(Vec::len),
        Some(2),
        "{p}"
    );
    assert!(p["groups"]
        .as_array()
        .unwrap()
        .iter()
        .any(|g| g["name"] == "FORCE_PLATFORM"));
    assert!(p["subjects"].is_array() && p["trial"].is_object(), "{p}");

    // Statistics split points and analog.
    let (status, stats) = srv.get_json("/v1/stats").await;
    assert_eq!(status, 200);
    let total = &stats["total"];
    assert!(
        total["analog"]["raw_bytes"].as_i64().unwrap() > 0,
        "{stats}"
    );
    assert_eq!(
        total["points"]["raw_bytes"].as_i64().unwrap()
            + total["analog"]["raw_bytes"].as_i64().unwrap(),
        total["raw_bytes"].as_i64().unwrap()
    );
    srv.stop().await;
    t.finish().await;
}

/// Model outputs (issue 49): every corpus C3D whose POINT:ANGLES, FORCES, MOMENTS or POWERS
/// list points keeps those apart from the markers — not among the take's points, listed with
/// their kinds and units, read by name in their own units equal to py-c3d's reading
/// (`scripts/c3d-outputs.py`) — and its C3D comes back with them where they were.
#[tokio::test(flavor = "multi_thread")]
async fn model_outputs_are_kept_apart_in_their_units() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let lenient = ReadOptions {
        lenient: true,
        ..ReadOptions::default()
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(root.join("c3d"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension().is_some_and(|e| e == "c3d")
                && std::fs::read(p)
                    .ok()
                    .and_then(|b| formats::read(&b, &lenient).ok())
                    .is_some_and(|l| l.extras.outputs.is_some())
        })
        .collect();
    files.sort();
    assert!(
        files.len() >= 20,
        "{} corpus files with model outputs",
        files.len()
    );
    let python = common::python();
    let (mut checked, mut against_py_c3d) = (0, 0);
    for path in &files {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let bytes = std::fs::read(path).unwrap();
        let ours = formats::read(&bytes, &lenient).unwrap();
        let outputs = ours.extras.outputs.as_ref().unwrap();
        // A quick codec: what is checked here is beside the points.
        let (status, report) = srv.post("lenient=true&codec=quant", bytes.clone()).await;
        assert_eq!(status, 201, "{name}: {report}");
        let id = report["id"].as_str().unwrap().to_string();
        let (_, _, body) = srv.get(&format!("/v1/takes/{id}")).await;
        let take: Value = serde_json::from_slice(&body).unwrap();
        let listed = take["meta"]["outputs"]
            .as_array()
            .expect("the take lists its outputs");
        assert_eq!(listed.len(), outputs.outputs.len(), "{name}");
        // (None at all when every point of the file is an output.)
        let points: Vec<&str> = take["meta"]["point_names"]
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        for o in listed {
            let n = o["name"].as_str().unwrap();
            assert!(!points.contains(&n), "{name}: {n} among the markers");
            assert!(o["unit"].as_str().is_some_and(|u| !u.is_empty()), "{o}");
        }
        // Every output over the whole take, in its unit.
        let (status, _, body) = srv
            .get(&format!("/v1/takes/{id}/outputs?format=json"))
            .await;
        assert_eq!(status, 200, "{name}: {}", String::from_utf8_lossy(&body));
        let answer: Value = serde_json::from_slice(&body).unwrap();
        let rows = answer["values"].as_array().unwrap();
        assert_eq!(rows.len(), ours.motion.frame_count(), "{name}");
        if let Some(python) = &python {
            let v = common::script(python, "c3d-outputs.py", [path.as_os_str()]);
            if let Some(theirs) = v["outputs"].as_object() {
                assert_eq!(theirs.len(), outputs.outputs.len(), "{name}");
                for (k, o) in outputs.outputs.iter().enumerate() {
                    let want = &theirs[&o.name];
                    assert_eq!(
                        want["kind"],
                        serde_json::to_value(o.kind).unwrap(),
                        "{name}"
                    );
                    assert_eq!(want["unit"], o.unit.as_str(), "{name}");
                    for (f, w) in want["values"].as_array().unwrap().iter().enumerate() {
                        let row = rows[f].as_array().unwrap();
                        for c in 0..3 {
                            let got = row[k * 3 + c].as_f64();
                            match w.as_array() {
                                Some(w) => {
                                    let w = w[c].as_f64().unwrap();
                                    let got = got.unwrap_or(f64::NAN);
                                    assert!(
                                        (got - w).abs() <= 1e-6 * w.abs().max(1.0),
                                        "{name} {} frame {f}: {got} against py-c3d's {w}",
                                        o.name
                                    );
                                }
                                None => assert!(got.is_none(), "{name} {} frame {f}", o.name),
                            }
                        }
                    }
                }
                against_py_c3d += 1;
            }
        }
        checked += 1;
    }
    // By name, a range, and what a name that is not one gets.
    let path = root.join("c3d/btkdata__others__Analysis.c3d");
    let bytes = std::fs::read(&path).unwrap();
    let ours = formats::read(&bytes, &lenient).unwrap();
    let (_, report) = srv.post("name=analysis", bytes.clone()).await;
    let id = report["id"].as_str().unwrap().to_string();
    let (status, _, body) = srv
        .get(&format!(
            "/v1/takes/{id}/outputs?format=csv&names=LHipAngles&start=5&end=9"
        ))
        .await;
    let text = String::from_utf8(body).unwrap();
    assert_eq!(status, 200, "{text}");
    let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    assert!(
        lines[0].contains("LHipAngles.x") && lines[0].contains("deg"),
        "{text}"
    );
    assert_eq!(lines.len(), 5, "{text}");
    let hip = ours.extras.outputs.as_ref().unwrap();
    let want = hip.get(5, hip.find("LHipAngles").unwrap());
    assert!(
        lines[1].contains(&format!("{}", want[0])),
        "{text} {want:?}"
    );
    let (status, _, body) = srv
        .get(&format!("/v1/takes/{id}/outputs?names=LHipAngle"))
        .await;
    let err: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(status, 400, "{err}");
    assert!(
        err["error"]["message"]
            .as_str()
            .unwrap()
            .contains("LHipAngles"),
        "{err}"
    );
    // The C3D back holds them where the upload had them, as py-c3d and ezc3d read it.
    let (status, _, c3d) = srv.get(&format!("/v1/takes/{id}/frames?format=c3d")).await;
    assert_eq!(status, 200);
    let back = formats::read(&c3d, &ReadOptions::default()).unwrap();
    assert_eq!(back.extras.outputs.as_ref().unwrap().outputs, hip.outputs);
    if let Some(python) = &python {
        let tol = report["max_mm"].as_f64().unwrap() * 1.0001 + 1e-3;
        let v = compare(
            python,
            &path,
            &c3d,
            &["--point-tol".into(), tol.to_string()],
        );
        assert_eq!(v["ok"], true, "{v}");
    }
    eprintln!("{checked} C3D files with model outputs checked, {against_py_c3d} against py-c3d");
    if python.is_some() {
        assert!(
            against_py_c3d >= 15,
            "{against_py_c3d} files read by py-c3d"
        );
    }
    srv.stop().await;
    t.finish().await;
}
