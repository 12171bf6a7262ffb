//! Bodies of the real corpus: every take's up axis against a manifest written from each
//! source's documentation (`tests/bodies/up.csv`, not from our code), the roles every
//! skeleton and standard marker set must resolve, and root motion that follows the pelvis
//! on every skeleton take.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[path = "bodies/manifest.rs"]
mod manifest;

use manifest::manifest;
use mocapstore::corpus::{self, Entry};
use mocapstore::motion::body::{Body, Given, Part, Role};
use mocapstore::motion::formats::{self, Loaded, ReadOptions};
use mocapstore::motion::transform::{whole, Options, Root};
use nalgebra::{UnitQuaternion, Vector3};

/// Takes that are no body: no role can be placed on them, and why.
const NOT_BODIES: &[(&str, &str)] = &[("bvh/misc/two_joint_toy.bvh", "two joints, Base and End")];

fn corpus() -> Option<(PathBuf, Vec<Entry>)> {
    corpus::for_tests()
}

fn read(root: &Path, e: &Entry) -> Option<Loaded> {
    let bytes = std::fs::read(root.join(&e.path)).ok()?;
    let opts = ReadOptions {
        lenient: true,
        ..ReadOptions::default()
    };
    formats::read(&bytes, &opts).ok()
}

fn body(l: &Loaded) -> Body {
    Body::of(&l.motion, Given::default(), l.up.as_ref()).expect("nothing given")
}

/// Every take the reference parser read stands up along the manifest's axis; today's
/// figures are in the closing note.
#[test]
fn every_corpus_take_stands_up_as_its_source_says() {
    let Some((root, entries)) = corpus() else {
        return;
    };
    let truth = manifest();
    let mut wrong = Vec::new();
    let mut checked = 0;
    for e in entries.iter().filter(|e| e.reference_ok != Some(false)) {
        let Some(l) = read(&root, e) else { continue };
        if l.motion.point_count() == 0 {
            continue;
        }
        let want = truth
            .get(&e.path)
            .unwrap_or_else(|| panic!("{} is not in tests/bodies/up.csv", e.path));
        let b = body(&l);
        checked += 1;
        if b.axes.up != Some(want.up) {
            wrong.push(format!(
                "{}: up {:?}, the manifest {} ({})",
                e.path, b.axes.up, want.up, b.axes.reason
            ));
        }
    }
    assert!(checked > 250, "{checked} takes checked");
    assert!(
        wrong.is_empty(),
        "{} of {checked}:\n{}",
        wrong.len(),
        wrong.join("\n")
    );
}

/// Every skeleton of the corpus places all its limb roles (but the ones that are no body);
/// so does every marker take laid out as Plug-in Gait full body or the anatomical names.
#[test]
fn every_corpus_body_knows_its_limbs() {
    let Some((root, entries)) = corpus() else {
        return;
    };
    let mut missing = Vec::new();
    let mut conventions: BTreeMap<String, usize> = BTreeMap::new();
    for e in entries.iter().filter(|e| e.format == "bvh") {
        let Some(l) = read(&root, e) else { continue };
        let b = body(&l);
        *conventions
            .entry(b.roles.convention.clone().unwrap_or_default())
            .or_default() += 1;
        let lacks = b.roles.missing_limbs();
        let listed = NOT_BODIES.iter().any(|(p, _)| *p == e.path);
        if listed {
            assert_eq!(
                lacks.len(),
                Role::limbs().len(),
                "{} is a body after all",
                e.path
            );
        } else if !lacks.is_empty() {
            missing.push(format!("{}: {lacks:?}", e.path));
        }
    }
    eprintln!("conventions: {conventions:?}");
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}

/// Marker takes whose set is not full body: the limb parts it has no markers for, and why
/// (from each file's labels, `POINT:DESCRIPTIONS` and its source's readme). Parts: `arms`
/// (shoulders, elbows, wrists), `forearms` (elbows, wrists), `legs` (hips down), `shins`
/// (knees down), and single parts.
const PARTIAL_SETS: &[(&[&str], &[&str], &str)] = &[
    (
        &[
            "c3d/btkdata__PiG__PiG_Calibration3_FF.c3d",
            "c3d/btkdata__PiG__PiG_Calibration3_FF_N18.c3d",
            "c3d/btkdata__PiG__PiG_Calibration3_noFF.c3d",
            "c3d/btkdata__PiG__PiG_Motion3_FF.c3d",
            "c3d/btkdata__PiG__PiG_Motion3_FF_N18.c3d",
            "c3d/btkdata__PiG__PiG_Motion3_noFF.c3d",
            "c3d/btkdata__sample04__sub_labels.c3d",
            "c3d/btkdata__sample09__PlugInC3D.c3d",
            "c3d/c3dio__sample_03__gait-pig-nz.c3d",
            "c3d/c3dio__sample_03__gait-pig.c3d",
            "c3d/c3dio__sample_07__16bitanalog.c3d",
            "c3d/c3dio__sample_09__VER4C3D.c3d",
            "c3d/c3dio__sample_10__TYPE-3.c3d",
            "c3d/c3dio__sample_11__2198928.c3d",
            "c3d/c3dio__sample_14__sample14.c3d",
            "c3d/c3dio__sample_25__analogfpscale03.c3d",
            "c3d/c3dio__sample_25__analogfpscale04.c3d",
            "c3d/c3dio__sample_25__analogfpscale04i.c3d",
            "c3d/c3dio__sample_33__bigparlove.c3d",
            "c3d/c3dio__Innovative_Sports_Training__Gait_with_EMG.c3d",
            "c3d/c3dio__Innovative_Sports_Training__Static_Pose.c3d",
            "c3d/btkdata__others__ADemo1_rewrite_c3d_pc_float.c3d",
            "c3d/btkdata__others__ADemo1_rewrite_c3d_pc_integer.c3d",
            "c3d/c3dio__Codamotion__codamotion_gaitwands_19970212.c3d",
            "c3d/c3dio__Codamotion__codamotion_gaitwands_20150204.c3d",
            "c3d/c3dio__sample_26__Standing_Hybrid_1.c3d",
            "c3d/c3dio__sample_26__Standing_Hybrid_2.c3d",
        ],
        &["arms"],
        "lower-body sets (Plug-in Gait and Helen Hayes lower body, Codamotion gait wands, \
         MotionMonitor, Qualisys clusters): no arm markers; a clavicle marker is no arm joint",
    ),
    (
        &[
            "c3d/c3dio__sample_26__Walking_Hybrid_1_1.c3d",
            "c3d/c3dio__sample_26__Walking_Hybrid_1_2.c3d",
            "c3d/c3dio__sample_26__Walking_Hybrid_1_3.c3d",
            "c3d/c3dio__sample_26__Walking_Hybrid_1_4.c3d",
            "c3d/c3dio__sample_26__Walking_Hybrid_1_5.c3d",
            "c3d/c3dio__sample_26__Walking_Hybrid_2.c3d",
        ],
        &["arms", "knee", "ankle"],
        "Qualisys lower-limb clusters: the joint landmarks are only in the static trials",
    ),
    (
        &[
            "c3d/c3dio__sample_26__Capture0002.c3d",
            "c3d/c3dio__sample_26__Capture0003.c3d",
            "c3d/c3dio__sample_26__Capture0004.c3d",
            "c3d/c3dio__sample_26__Capture0008_Standing.c3d",
            "c3d/c3dio__sample_23__Vicon_analysis.c3d",
            "c3d/c3dio__sample_30__admarche2.c3d",
        ],
        &["forearms"],
        "the shoulder is the only arm marker",
    ),
    (
        &["c3d/c3dio__sample_30__marche281.c3d"],
        &["ankle"],
        "no malleolus markers (TB is mid-tibia, TLN the heel)",
    ),
    (
        &["c3d/c3dio__sample_27__kyowadengyo.c3d"],
        &["forearms", "hip"],
        "a Kyowa Dengyo set: shoulders but no forearm markers, trochanters but no ASIS",
    ),
    (
        &["c3d/btkdata__others__shd01.c3d"],
        &["shins"],
        "an upper-body Plug-in Gait shoulder trial: no leg markers below the pelvis",
    ),
    (
        &["c3d/btkdata__sample21__sample21.c3d"],
        &["arms", "left_knee", "left_ankle", "left_toe"],
        "a right-leg set",
    ),
    (
        &[
            "trc/TRCSamples__Anto.trc",
            "trc/TRCSamples__UpperLimbStatic.trc",
        ],
        &["legs"],
        "an upper-limb wheelchair set (Roue is the wheel, Dossier the backrest)",
    ),
    (
        &[
            "c3d/c3dio__sample_37__ART-Human_2persons_integer.c3d",
            "c3d/c3dio__sample_37__ART-Human_hands_real_no6dof.c3d",
            "c3d/c3dio__sample_37__ART-Human_real.c3d",
            "c3d/c3dio__sample_37__ART-Human_tools_integer_6dofLimbs.c3d",
        ],
        &["toe"],
        "the A.R.T. DTrack body model ends at the foot segment",
    ),
    (
        &["c3d/btkdata__others__mocap36.c3d"],
        &["arms", "legs"],
        "OptiTrack Arena's numbered markers (Hip1, LUArm1…): no documented numbering to read",
    ),
    (
        &["c3d/btkdata__sample22__BKINtechnologies.c3d"],
        &["arms", "legs"],
        "a KINARM robot: two hand points",
    ),
];

/// Whether limb role `role` is among `parts` (see [`PARTIAL_SETS`]).
fn lacks(parts: &[&str], role: Role) -> bool {
    let name = role.to_string();
    parts.iter().any(|&p| match p {
        "arms" => ["shoulder", "elbow", "wrist"]
            .iter()
            .any(|w| name.ends_with(w)),
        "forearms" => ["elbow", "wrist"].iter().any(|w| name.ends_with(w)),
        "legs" => ["hip", "knee", "ankle", "toe"]
            .iter()
            .any(|w| name.ends_with(w)),
        "shins" => ["knee", "ankle", "toe"].iter().any(|w| name.ends_with(w)),
        // One side's part (left_knee), or both sides' (knee).
        one if one.contains('_') => name == one,
        one => name.ends_with(one),
    })
}

/// Every marker take laid out by a known marker set places all its limb roles, but the
/// sets [`PARTIAL_SETS`] lists, which lack only what they say.
#[test]
fn every_corpus_marker_set_knows_its_limbs() {
    let Some((root, entries)) = corpus() else {
        return;
    };
    let mut wrong = Vec::new();
    let mut full = BTreeMap::<String, usize>::new();
    for e in entries
        .iter()
        .filter(|e| e.format == "c3d" || e.format == "trc")
    {
        let Some(l) = read(&root, e) else { continue };
        let b = body(&l);
        let Some(convention) = b.roles.convention.clone() else {
            // Unlabelled or unnamed points: no set to place roles by.
            assert!(b.roles.roles.is_empty(), "{}", e.path);
            continue;
        };
        let missing = b.roles.missing_limbs();
        match PARTIAL_SETS
            .iter()
            .find(|(files, _, _)| files.contains(&e.path.as_str()))
        {
            Some((_, parts, why)) => {
                let extra: Vec<_> = missing.iter().filter(|r| !lacks(parts, **r)).collect();
                if !extra.is_empty() {
                    wrong.push(format!("{}: {extra:?} missing, beyond {why}", e.path));
                }
                if missing.is_empty() {
                    wrong.push(format!("{}: listed as partial, places every limb", e.path));
                }
            }
            None if !missing.is_empty() => {
                wrong.push(format!("{} ({convention}): {missing:?} missing", e.path));
            }
            None => *full.entry(convention).or_default() += 1,
        }
    }
    eprintln!("marker takes placing every limb, per set: {full:?}");
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    assert!(full.values().sum::<usize>() >= 25, "{full:?}");
}

/// `root=in-place` on every corpus skeleton: the pelvis's horizontal path within 1 mm of
/// zero in every frame, every joint where it was relative to the pelvis; `extract` gives
/// the path back (FK of its skeleton is the source). Checked against the source's own FK.
#[test]
fn root_motion_follows_the_pelvis_on_every_corpus_skeleton() {
    let Some((root, entries)) = corpus() else {
        return;
    };
    let mut checked = 0;
    for e in entries.iter().filter(|e| e.format == "bvh") {
        if NOT_BODIES.iter().any(|(p, _)| *p == e.path) {
            continue;
        }
        let Some(l) = read(&root, e) else { continue };
        let m = &l.motion;
        let b = body(&l);
        let up = b.axes.up.expect("every corpus skeleton knows its up");
        let pelvis = b.roles.points(Role::Pelvis, &m.point_names)[0];
        let metres = |o: Options| Options {
            metres_per_unit: Some(1.0),
            ..o
        };
        let inplace = whole::apply(
            m,
            &b,
            &metres(Options {
                root: Root::InPlace,
                ..Options::default()
            }),
        )
        .unwrap();
        let mpu = m.unit.metres_per_unit as f32;
        let n = m.point_count();
        for f in 0..m.frame_count() {
            let (src, out) = (m.frame(f), inplace.frame(f));
            let p = &out[pelvis * 3..pelvis * 3 + 3];
            for a in up.across() {
                assert!(p[a].abs() < 1e-3, "{} frame {f}: pelvis at {p:?} m", e.path);
            }
            assert!((p[up.index()] - src[pelvis * 3 + up.index()] * mpu).abs() < 1e-4);
            for j in 0..n {
                for k in 0..3 {
                    let was = (src[j * 3 + k] - src[pelvis * 3 + k]) * mpu;
                    let now = out[j * 3 + k] - out[pelvis * 3 + k];
                    assert!((was - now).abs() < 1e-4, "{} frame {f} joint {j}", e.path);
                }
            }
        }
        let extract = whole::apply(
            m,
            &b,
            &metres(Options {
                root: Root::Extract,
                ..Options::default()
            }),
        )
        .unwrap();
        assert_eq!(extract.point_names[0], "root_motion");
        for f in 0..m.frame_count() {
            let (src, out) = (m.frame(f), extract.frame(f));
            for j in 0..n {
                for k in 0..3 {
                    let d = (src[j * 3 + k] * mpu - out[(j + 1) * 3 + k]).abs();
                    assert!(d < 1e-4, "{} frame {f} joint {j}: {d} m", e.path);
                }
            }
            let path = &out[..3];
            let floor = b.axes.floor_m.unwrap() as f32 * up.sign() as f32;
            assert!((path[up.index()] - floor).abs() < 1e-5);
        }
        // The heading apart: the root motion turns about up, and in its frame the body
        // (its hips and shoulders, left to right) faces its forward in every frame.
        let rig = extract.skeleton.as_ref().unwrap();
        let channels = &rig.joints[0].channels;
        assert_eq!(channels.len(), 4, "{}: {channels:?}", e.path);
        assert_eq!(channels[3].rotation_axis(), Some(up.index()), "{}", e.path);
        let forward = b
            .axes
            .forward
            .expect("every corpus skeleton faces a way")
            .vector();
        let joint = |role: Role| b.roles.points(role, &m.point_names)[0] + 1;
        let pairs =
            [Part::Hip, Part::Shoulder].map(|p| (joint(Role::left(p)), joint(Role::right(p))));
        let u = up.vector();
        for f in 0..m.frame_count() {
            let out = extract.frame(f);
            let at =
                |j: usize| Vector3::new(out[j * 3], out[j * 3 + 1], out[j * 3 + 2]).cast::<f64>();
            let across: Vector3<f64> = pairs
                .iter()
                .map(|&(l, r)| {
                    let d = at(r) - at(l);
                    (d - u * d.dot(&u)).normalize()
                })
                .sum();
            let facing = u.cross(&across).normalize();
            let yaw = rig.frame_values(f)[3].to_radians() * up.sign();
            let turn_back =
                UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(u), -yaw);
            let off = (turn_back * facing).dot(&forward).clamp(-1.0, 1.0).acos();
            assert!(
                off.to_degrees() < 0.1,
                "{} frame {f}: the body faces {:.2}° off forward",
                e.path,
                off.to_degrees()
            );
        }
        checked += 1;
    }
    assert!(checked > 150, "{checked}");
}
