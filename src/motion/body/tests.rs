use super::*;
use crate::motion::synthetic::dancer;

/// `m`'s points (and nothing else: no skeleton) moved by `f`.
fn moved(m: &Motion, f: impl Fn([f32; 3]) -> [f32; 3]) -> Motion {
    let positions = m
        .positions()
        .chunks_exact(3)
        .flat_map(|p| f([p[0], p[1], p[2]]))
        .collect();
    Motion::new(
        m.fps,
        m.unit.clone(),
        m.point_names.clone(),
        positions,
        None,
    )
    .unwrap()
}

/// `m`'s points under names no convention knows (`m0`, `m1`, …), without its skeleton.
fn anonymous(m: &Motion) -> Motion {
    let names: Vec<String> = (0..m.point_count()).map(|i| format!("m{i}")).collect();
    Motion::new(m.fps, m.unit.clone(), names, m.positions().to_vec(), None).unwrap()
}

fn axes(m: &Motion, roles: &Roles) -> Axes {
    let joints = m.skeleton.as_ref().map(|s| s.joints.as_slice());
    derive(m, joints, roles, Given::default(), None).unwrap()
}

/// The dancer stands on +Y and faces +Z (its toes point there, its left is +X); turned to
/// Z-up, it stands on +Z and faces −Y. The floor is under its feet.
#[test]
fn up_and_forward_from_the_body() {
    let m = dancer(240, 120.0, 1);
    let roles = Roles::of_skeleton(&m.skeleton.as_ref().unwrap().joints);
    assert!(roles
        .missing_limbs()
        .iter()
        .all(|r| matches!(r, Role::Limb(_, Part::Toe))));
    let a = axes(&m, &roles);
    assert_eq!(
        (a.up, a.forward),
        (Some(Axis::Y), Some(Axis::Z)),
        "{}",
        a.reason
    );
    assert_eq!(a.up_from, Some(Source::Anatomy));
    let lowest = m
        .positions()
        .chunks_exact(3)
        .map(|s| f64::from(s[1]))
        .fold(f64::MAX, f64::min);
    let floor = a.floor_m.unwrap() / m.unit.metres_per_unit;
    assert!(
        floor >= lowest && floor < lowest + 5.0,
        "{floor} vs {lowest}"
    );

    let turned = moved(&m, |[x, y, z]| [x, -z, y]);
    let a = axes(&turned, &Roles::of_markers(&m.point_names));
    assert_eq!(a.up, Some(Axis::Z), "{}", a.reason);
    assert_eq!(a.forward, Some(Axis::Y.flipped()), "{}", a.reason);
    let upside_down = moved(&m, |[x, y, z]| [x, -y, -z]);
    let a = axes(&upside_down, &Roles::of_markers(&m.point_names));
    assert_eq!(a.up, Some(Axis::Y.flipped()), "{}", a.reason);
}

/// A long walk along Z, Y-up: the figure spans metres along Z and under two along Y, which
/// fooled the extent rule; the body is not fooled.
#[test]
fn a_long_walk_stands_upright() {
    let m = dancer(1200, 30.0, 2);
    let walk = moved(&m, |[x, y, z]| [z, y, -x]);
    let span = |axis: usize| {
        let v: Vec<f32> = walk.positions().chunks_exact(3).map(|p| p[axis]).collect();
        v.iter().cloned().fold(f32::MIN, f32::max) - v.iter().cloned().fold(f32::MAX, f32::min)
    };
    assert!(span(2) > 10.0 * span(1), "a walk much longer than tall");
    let a = axes(&walk, &Roles::of_markers(&m.point_names));
    assert_eq!(a.up, Some(Axis::Y), "{}", a.reason);
    assert_eq!(a.forward, Some(Axis::X), "{}", a.reason);
}

/// Nothing to stand on: the format's convention, or nothing, saying why; what a user gives
/// wins, and must make sense.
#[test]
fn without_a_body_the_prior_or_nothing() {
    let m = dancer(30, 30.0, 3);
    let anon = anonymous(&m);
    let names = anon.point_names.clone();
    let roles = Roles::of_markers(&names);
    assert_eq!(roles.convention, None);
    assert_eq!(roles.unplaced.len(), 20);
    let a = axes(&anon, &roles);
    assert_eq!((a.up, a.forward, a.up_from), (None, None, None));
    assert!(
        a.reason.contains("no head over feet") && a.reason.contains("up="),
        "{}",
        a.reason
    );
    let prior = Prior {
        up: Axis::Z,
        says: "C3D is Z-up by convention".into(),
    };
    let a = derive(&anon, None, &roles, Given::default(), Some(&prior)).unwrap();
    assert_eq!((a.up, a.up_from), (Some(Axis::Z), Some(Source::Format)));
    assert!(a.reason.contains("C3D is Z-up"), "{}", a.reason);
    // Given wins over anatomy.
    let named = Roles::of_markers(&m.point_names);
    let given = Given {
        up: Some(Axis::X),
        forward: Some(Axis::Y),
    };
    let a = derive(&m, None, &named, given, Some(&prior)).unwrap();
    assert_eq!((a.up, a.forward), (Some(Axis::X), Some(Axis::Y)));
    assert_eq!(
        (a.up_from, a.forward_from),
        (Some(Source::Given), Some(Source::Given))
    );
    let bad = Given {
        up: Some(Axis::Y),
        forward: Some(Axis::Y.flipped()),
    };
    assert!(derive(&m, None, &named, bad, None).is_err());
}

/// A rig whose names nothing knows gets its roles from its shape: the same joints the names
/// give, and the sides the right way round.
#[test]
fn roles_from_the_shape_of_an_unnamed_rig() {
    let m = dancer(2, 30.0, 4);
    let joints = &m.skeleton.as_ref().unwrap().joints;
    let named = Roles::of_skeleton(joints);
    let mut anon = joints.clone();
    for (i, j) in anon.iter_mut().enumerate() {
        j.name = format!("j{i}");
    }
    let shaped = Roles::of_skeleton(&anon);
    assert_eq!(shaped.convention.as_deref(), Some("topology"));
    let index = |names: &[String], all: &[Joint]| -> Vec<usize> {
        names
            .iter()
            .map(|n| all.iter().position(|j| &j.name == n).unwrap())
            .collect()
    };
    for (role, names) in &named.roles {
        let got = shaped
            .roles
            .get(role)
            .unwrap_or_else(|| panic!("{role} unplaced"));
        if *role == Role::Spine {
            // The names know Spine; the shape finds the chain to the chest.
            assert!(index(names, joints)
                .iter()
                .all(|i| index(got, &anon).contains(i)));
        } else {
            assert_eq!(index(got, &anon), index(names, joints), "{role}");
        }
    }
    // The toes are the feet's end sites, which names did not place.
    assert!(shaped.missing_limbs().is_empty(), "{:?}", shaped.unplaced);
    // Mirrored left to right (x negated), the sides follow the body, not the order.
    let mut mirrored = anon.clone();
    for j in &mut mirrored {
        j.offset[0] = -j.offset[0];
    }
    let m = Roles::of_skeleton(&mirrored);
    assert_eq!(
        m.roles[&Role::left(Part::Knee)],
        shaped.roles[&Role::right(Part::Knee)]
    );
}

/// Plug-in Gait markers (millimetres, Y-up, facing +Z, left +X) on a figure stepping in
/// place for `frames` frames, one foot lifted 10 cm at a time; leaning `lean` degrees
/// forward, each frame set down on y = 0, and carried `run` mm along +Z over the take.
fn stepper(frames: usize, lean: f32, run: f32) -> Motion {
    const MARKERS: [(&str, [f32; 3]); 17] = [
        ("LFHD", [80.0, 1700.0, 60.0]),
        ("RFHD", [-80.0, 1700.0, 60.0]),
        ("C7", [0.0, 1500.0, -60.0]),
        ("LSHO", [180.0, 1450.0, 0.0]),
        ("RSHO", [-180.0, 1450.0, 0.0]),
        ("LASI", [120.0, 1000.0, 60.0]),
        ("RASI", [-120.0, 1000.0, 60.0]),
        ("LPSI", [50.0, 1000.0, -100.0]),
        ("RPSI", [-50.0, 1000.0, -100.0]),
        ("LKNE", [100.0, 500.0, 0.0]),
        ("RKNE", [-100.0, 500.0, 0.0]),
        ("LANK", [100.0, 80.0, 0.0]),
        ("RANK", [-100.0, 80.0, 0.0]),
        ("LTOE", [100.0, 30.0, 150.0]),
        ("RTOE", [-100.0, 30.0, 150.0]),
        ("LELB", [250.0, 1150.0, 0.0]),
        ("RELB", [-250.0, 1150.0, 0.0]),
    ];
    let (sin, cos) = lean.to_radians().sin_cos();
    let mut positions = Vec::new();
    for f in 0..frames {
        let phase = std::f32::consts::TAU * f as f32 / 100.0;
        let pose: Vec<[f32; 3]> = MARKERS
            .iter()
            .map(|(name, [x, y, z])| {
                let lift = match name.as_bytes()[0] {
                    b'L' if name.ends_with("ANK") || name.ends_with("TOE") => phase.sin(),
                    b'R' if name.ends_with("ANK") || name.ends_with("TOE") => -phase.sin(),
                    _ => 0.0,
                };
                let y = y + 100.0 * lift.max(0.0);
                [*x, y * cos - z * sin, z * cos + y * sin]
            })
            .collect();
        let lowest = pose.iter().map(|p| p[1]).fold(f32::MAX, f32::min);
        let along = run * f as f32 / frames as f32;
        positions.extend(
            pose.iter()
                .flat_map(|p| [p[0], p[1] - lowest, p[2] + along]),
        );
    }
    let names = MARKERS.iter().map(|(n, _)| n.to_string()).collect();
    Motion::new(
        100.0,
        crate::motion::units::Unit::millimetres(),
        names,
        positions,
        None,
    )
    .unwrap()
}

/// Markers no role names, standing on the lab's floor at the origin, a person's height
/// tall: the floor tells up. Lifted off the origin's floor, nothing does.
#[test]
fn unnamed_points_stand_up_by_the_lab_floor() {
    let m = moved(&stepper(300, 0.0, 0.0), |[x, y, z]| [x, -z, y]);
    let anon = anonymous(&m);
    let names = anon.point_names.clone();
    let roles = Roles::of_markers(&names);
    let a = axes(&anon, &roles);
    assert_eq!(
        (a.up, a.up_from),
        (Some(Axis::Z), Some(Source::Floor)),
        "{}",
        a.reason
    );
    let lifted = moved(&anon, |[x, y, z]| [x, y, z + 800.0]);
    let a = axes(&lifted, &roles);
    assert_eq!(a.up, None, "{}", a.reason);
}

/// A sprint start: the body leans 65° along the run (+Z) and travels 3 m along it, its
/// feet on the floor (Y-up): head over feet is nearer Z than Y in every frame, but the
/// feet keep a floor only along Y. Upright, the same figure stands along Y plainly.
#[test]
fn a_sprinter_leaning_along_the_run_stands_on_the_floor() {
    let names = stepper(1, 0.0, 0.0).point_names;
    let sprint = stepper(300, 65.0, 3000.0);
    let a = axes(&sprint, &Roles::of_markers(&names));
    assert_eq!(
        (a.up, a.forward),
        (Some(Axis::Y), Some(Axis::Z)),
        "{}",
        a.reason
    );
    assert!(a.reason.contains("leans along z"), "{}", a.reason);
    let a = axes(&stepper(300, 5.0, 3000.0), &Roles::of_markers(&names));
    assert_eq!(a.up, Some(Axis::Y), "{}", a.reason);
    assert!(!a.reason.contains("leans"), "{}", a.reason);
}

/// A marker left at exactly the origin in every frame (never seen, written as 0, 0, 0
/// with a valid residual) is missing, not a head on the floor: up comes from what is seen.
#[test]
fn markers_at_the_origin_are_missing() {
    let m = moved(&stepper(120, 0.0, 0.0), |[x, y, z]| [x, -z, y]);
    let roles = Roles::of_markers(&m.point_names);
    let head = roles.points(Role::Head, &m.point_names);
    let neck = roles.points(Role::Neck, &m.point_names);
    let n = m.point_count();
    let mut positions = m.positions().to_vec();
    for f in 0..m.frame_count() {
        for &p in head.iter().chain(&neck) {
            positions[(f * n + p) * 3..(f * n + p) * 3 + 3].fill(0.0);
        }
    }
    let blind = Motion::new(
        m.fps,
        m.unit.clone(),
        m.point_names.clone(),
        positions,
        None,
    )
    .unwrap();
    let a = axes(&blind, &roles);
    assert_eq!(a.up, Some(Axis::Z), "{}", a.reason);
    assert!(
        a.reason.contains("shoulders above the ankles"),
        "{}",
        a.reason
    );
}

#[test]
fn centroids_average_what_is_present() {
    // Two frames of three points; groups {0, 1}, {2}, {}.
    let n = f32::NAN;
    let pos = [
        0.0, 0.0, 0.0, 2.0, 2.0, 2.0, 5.0, 5.0, 5.0, //
        n, n, n, 4.0, 4.0, 4.0, n, n, n,
    ];
    let c = centroids(&pos, 3, &[vec![0, 1], vec![2], vec![]]);
    assert_eq!(&c[0..3], &[1.0, 1.0, 1.0]);
    assert_eq!(&c[3..6], &[5.0, 5.0, 5.0]);
    assert!(c[6..9].iter().all(|v| v.is_nan()));
    assert_eq!(&c[9..12], &[4.0, 4.0, 4.0]);
    assert!(c[12..18].iter().all(|v| v.is_nan()));
}
