use nalgebra::{Rotation3, Vector3};

use super::*;
use crate::motion::body::{Part, Role, Roles, Side};
use crate::motion::rigs;
use crate::motion::skeleton::{rest_values, Animation};
use crate::motion::transform::Axis;
use crate::rng::Rng;

fn figure<'a>(joints: &'a [Joint], roles: &'a Roles) -> Figure<'a> {
    Figure {
        joints,
        rest: rest_values(joints),
        roles,
        up: Axis::Y,
        floor: 0.0,
        metres_per_unit: 1.0,
    }
}

/// `frames` poses of `joints`: every rotation channel within ±`degrees` of rest, the root
/// walking along +Z at its rest height.
fn poses(joints: &[Joint], frames: usize, degrees: f64, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    let rest = rest_values(joints);
    let mut out = Vec::new();
    for f in 0..frames {
        let mut k = 0;
        for j in joints {
            for c in &j.channels {
                let v = match c.axis() {
                    (_, true) => (rng.unit() * 2.0 - 1.0) * degrees,
                    (2, false) if j.parent.is_none() => rest[k] + 0.05 * f as f64,
                    _ => rest[k],
                };
                out.push(v);
                k += 1;
            }
        }
    }
    out
}

fn positions(joints: &[Joint], values: Vec<f64>) -> Vec<Vector3<f64>> {
    Animation::new(joints.to_vec(), values)
        .unwrap()
        .forward_kinematics()
        .chunks_exact(3)
        .map(|p| Vector3::new(p[0], p[1], p[2]))
        .collect()
}

/// The angle (degrees) of every mapped bone of every frame between the target's and the
/// source's (turned to the target's world).
fn bone_angles(r: &mut Retarget, source: &[Joint], src: &[f64], frames: usize) -> Vec<f64> {
    let mut written = Vec::new();
    let cc = src.len() / frames;
    for f in 0..frames {
        r.frame(&src[f * cc..(f + 1) * cc], &mut written);
    }
    let sp = positions(source, src.to_vec());
    let tp = positions(r.joints(), written);
    let (ns, nt) = (source.len(), r.joints().len());
    let m = r.mapping();
    let mut out = Vec::new();
    for f in 0..frames {
        for b in m.bones(r.joints()).into_iter().filter(|b| !b.shape) {
            let (pa, pc) = (&m.pairs[b.from], &m.pairs[b.to]);
            let t = tp[f * nt + pc.target] - tp[f * nt + pa.target];
            let s = m.turn() * (sp[f * ns + pc.source] - sp[f * ns + pa.source]);
            if t.norm() > 1e-9 && s.norm() > 1e-9 {
                out.push(t.angle(&s).to_degrees());
            }
        }
    }
    out
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// A rig put on itself is itself: every joint where it was, in every frame.
#[test]
fn a_rig_on_itself_is_unchanged() {
    for rig in rigs::all() {
        let roles = Roles::of_skeleton(&rig.joints);
        let f = figure(&rig.joints, &roles);
        let mut r = Retarget::new(&f, &f).unwrap();
        assert!((r.mapping().scale - 1.0).abs() < 1e-12);
        for p in &r.mapping().pairs {
            assert!(
                p.correction_degrees() < 1e-6,
                "{} {:?} {}",
                rig.name,
                p.role,
                p.correction_degrees()
            );
        }
        let src = poses(&rig.joints, 10, 60.0, 7);
        let mut out = Vec::new();
        for f in src.chunks_exact(r.channels_in()) {
            r.frame(f, &mut out);
        }
        let (a, b) = (positions(&rig.joints, src), positions(&rig.joints, out));
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!((x - y).norm() < 1e-9, "{} point {i}: {x} vs {y}", rig.name);
        }
    }
}

/// Between two rigs of other proportions and joints (Mixamo's three spine joints and
/// clavicles, SMPL's), every mapped bone points where the source's does (but those whose
/// direction is the rig's own shape, [`Bone::shape`]).
#[test]
fn bones_point_where_the_sources_do_between_rigs() {
    let all = rigs::all();
    for s in &all {
        for t in &all {
            let (rs, rt) = (Roles::of_skeleton(&s.joints), Roles::of_skeleton(&t.joints));
            let mut r = Retarget::new(&figure(&s.joints, &rs), &figure(&t.joints, &rt)).unwrap();
            assert!(r.mapping().missing.is_empty(), "{} → {}", s.name, t.name);
            let src = poses(&s.joints, 20, 45.0, 3);
            let mut angles = bone_angles(&mut r, &s.joints, &src, 20);
            assert!(
                angles.len() >= 20 * 17,
                "{} → {}: {}",
                s.name,
                t.name,
                angles.len()
            );
            let med = median(&mut angles);
            let p95 = angles[angles.len() * 95 / 100];
            assert!(
                med < 0.1 && p95 < 2.0,
                "{} → {}: median {med:.2}°, 95th {p95:.2}°",
                s.name,
                t.name
            );
        }
    }
}

/// Mixamo's rig with its arms 40° down (an A-pose, as Unreal's mannequin rests).
fn a_pose() -> Vec<Joint> {
    let mut joints = rigs::named("mixamo").unwrap().joints;
    let names: Vec<String> = joints.iter().map(|j| j.name.clone()).collect();
    for side in ["Left", "Right"] {
        let arm = names
            .iter()
            .position(|n| n == &format!("mixamorig:{side}Arm"))
            .unwrap();
        let sign = if side == "Left" { -1.0 } else { 1.0 };
        let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), sign * 40f64.to_radians());
        for i in arm + 1..joints.len() {
            let mut at = joints[i].parent;
            let below = loop {
                match at {
                    Some(a) if a == arm => break true,
                    Some(a) => at = joints[a].parent,
                    None => break false,
                }
            };
            if below {
                joints[i].offset = (turn * Vector3::from(joints[i].offset)).into();
            }
        }
    }
    joints
}

/// A T-pose put on an A-pose rig raises its arms 40° to stand in a T; the correction says
/// so; and back.
#[test]
fn a_t_pose_on_an_a_pose_rig_stands_in_a_t() {
    let t_pose = rigs::named("mixamo").unwrap().joints;
    let a = a_pose();
    let (rt, ra) = (Roles::of_skeleton(&t_pose), Roles::of_skeleton(&a));
    let names: Vec<String> = a.iter().map(|j| j.name.clone()).collect();
    let at = |role: Role| ra.points(role, &names)[0];
    for (from, to, roles_from, roles_to, level) in [
        (&t_pose, &a, &rt, &ra, true),
        (&a, &t_pose, &ra, &rt, false),
    ] {
        let mut r = Retarget::new(&figure(from, roles_from), &figure(to, roles_to)).unwrap();
        let shoulder = r
            .mapping()
            .pairs
            .iter()
            .find(|p| p.role == Some(Role::Limb(Side::Left, Part::Shoulder)))
            .unwrap();
        assert!((shoulder.correction_degrees() - 40.0).abs() < 0.5);
        let mut out = Vec::new();
        r.frame(&rest_values(from), &mut out);
        let p = positions(to, out);
        for side in Side::BOTH {
            let (s, w) = (
                p[at(Role::Limb(side, Part::Shoulder))],
                p[at(Role::Limb(side, Part::Wrist))],
            );
            let drop = ((s.y - w.y) / (w - s).norm()).asin().to_degrees();
            let want = if level { 0.0 } else { 40.0 };
            assert!((drop - want).abs() < 0.5, "{side:?}: {drop:.2}°");
        }
    }
}

/// The pelvis runs the source's path scaled by the legs, its height above the floor kept
/// in proportion, in the target's units and up axis.
#[test]
fn the_path_is_scaled_by_the_legs_onto_the_targets_floor() {
    let smpl = rigs::named("smpl").unwrap().joints;
    let mixamo = rigs::named("mixamo").unwrap().joints;
    let (rs, rm) = (Roles::of_skeleton(&smpl), Roles::of_skeleton(&mixamo));
    // The source in centimetres, Z up, standing on a floor 10 cm below its origin: SMPL
    // turned from Y-up to Z-up.
    let turn = Axis::Y.turn_to(Axis::Z).unwrap();
    let mut zup = smpl.clone();
    for j in &mut zup {
        j.offset = (turn * Vector3::from(j.offset) * 100.0).into();
    }
    zup[0].offset[2] += -10.0;
    let source = Figure {
        up: Axis::Z,
        floor: 100.0 * rest_places_lowest(&smpl) - 10.0,
        metres_per_unit: 0.01,
        ..figure(&zup, &rs)
    };
    let mut r = Retarget::new(&source, &figure(&mixamo, &rm)).unwrap();
    let scale = r.mapping().scale;
    assert!(scale > 0.8 && scale < 1.3, "{scale}");
    let mut src = rest_values(&zup);
    // The root 1 m along x and 20 cm higher.
    src[0] += 100.0;
    src[2] += 20.0;
    let mut out = Vec::new();
    r.frame(&src, &mut out);
    let p = positions(&mixamo, out);
    let names: Vec<String> = mixamo.iter().map(|j| j.name.clone()).collect();
    let pelvis = p[rm.points(Role::Pelvis, &names)[0]];
    let rest_pelvis = mixamo[0].offset[1];
    let smpl_pelvis = smpl[0].offset[1] - rest_places_lowest(&smpl);
    // Up: the source's pelvis height above its floor, scaled; along: 1 m scaled.
    assert!((pelvis.x - scale).abs() < 1e-9, "{pelvis}");
    assert!(
        (pelvis.y - scale * (smpl_pelvis + 0.2)).abs() < 1e-9,
        "{pelvis} (rest {rest_pelvis})"
    );
}

fn rest_places_lowest(joints: &[Joint]) -> f64 {
    crate::motion::skeleton::rest_places(joints)
        .iter()
        .map(|p| p[1])
        .fold(f64::MAX, f64::min)
}

/// A rig turned Z-up (its offsets, path and every joint's frame turned: the same motion in
/// another world) put on the rig as it stands, Y-up, gives back the motion itself: every
/// joint's rotation relative to its parent, twist about its bone included (which aiming
/// bones alone would not settle), and every joint's place.
#[test]
fn a_rig_in_another_world_comes_back_whole() {
    use crate::motion::rotation::{euler_order, from_euler, to_euler};
    let rig = rigs::named("mixamo").unwrap().joints;
    let roles = Roles::of_skeleton(&rig);
    let turn = Axis::Y.turn_to(Axis::Z).unwrap();
    let mut zup = rig.clone();
    for j in &mut zup {
        j.offset = (turn * Vector3::from(j.offset)).into();
    }
    let src = poses(&rig, 12, 50.0, 11);
    let cc = src.len() / 12;
    let order = euler_order(&rig[1].channels).unwrap();
    let q_turn =
        nalgebra::UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(turn));
    // The root's place turned and every joint's rotation conjugated by the turn (its
    // offsets are turned, so its frame is too).
    let turned: Vec<f64> = src
        .chunks_exact(cc)
        .flat_map(|f| {
            let mut f = f.to_vec();
            let p = turn * Vector3::new(f[0], f[1], f[2]);
            f[..3].copy_from_slice(p.as_slice());
            let mut start = 0;
            for j in &rig {
                let at = start + j.channels.len() - 3;
                if !j.end_site {
                    let q = q_turn
                        * from_euler(order, [f[at], f[at + 1], f[at + 2]])
                        * q_turn.inverse();
                    f[at..at + 3].copy_from_slice(&to_euler(&q, order, None));
                }
                start += j.channels.len();
            }
            f
        })
        .collect();
    let source = Figure {
        up: Axis::Z,
        ..figure(&zup, &roles)
    };
    let mut r = Retarget::new(&source, &figure(&rig, &roles)).unwrap();
    let mut out = Vec::new();
    for f in turned.chunks_exact(cc) {
        r.frame(f, &mut out);
    }
    for (f, (a, b)) in src.chunks_exact(cc).zip(out.chunks_exact(cc)).enumerate() {
        let mut start = 0;
        for joint in &rig {
            let n = joint.channels.len();
            let (la, lb) = (
                crate::motion::skeleton::local_rotation(joint, &a[start..start + n]),
                crate::motion::skeleton::local_rotation(joint, &b[start..start + n]),
            );
            assert!(
                (la - lb).norm() < 1e-9,
                "frame {f} {}: rotations {:e} apart",
                joint.name,
                (la - lb).norm()
            );
            start += n;
        }
    }
    let (a, b) = (positions(&rig, src), positions(&rig, out));
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).norm() < 1e-9, "{x} vs {y}");
    }
}
