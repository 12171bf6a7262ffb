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
