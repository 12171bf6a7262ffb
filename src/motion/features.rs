//! Motion features for finding motion by motion: a compact descriptor of each window of a
//! take (1 s, every half second), taken in the body's own frame so that where a take was
//! captured, which way it faces and how tall the performer is do not count, while left and
//! right, and turning left or right, do.
//!
//! # The body frame
//! The input is a take's frames at [`RATE`], in metres, +Y up (what the read path gives with
//! `fps=30&unit=m&up=y`), as one point per body role ([`Role::all`], the centroids the body
//! places; NaN where none). Each frame is turned about +Y so that the body faces +Z: its
//! heading is the horizontal perpendicular of the hip and shoulder lines (left to right),
//! so a mirror image is a different motion. Positions are taken from the pelvis and
//! divided by the take's leg length (hip to knee to ankle, the median over frames), so a
//! child's walk and an adult's are alike.
//!
//! # A window's descriptor ([`DIMS`] numbers)
//! Over the window's frames, for the key roles ([`KEY_ROLES`]: head, elbows, wrists, knees,
//! ankles): the mean and the spread of each one's place in the body frame, and the root
//! mean square of its velocity there (what moves, and how fast); the pelvis's height, and
//! its velocity along the body's right, up and forward axes; and the heading's turning
//! rate (positive: turning left, anticlockwise seen from above). Each group is scaled to
//! comparable magnitudes ([`SCALES`]), so that Euclidean distance between descriptors is a
//! distance between motions.

use super::body::{Part, Role};

/// Frames per second a take's features are taken at.
pub const RATE: f64 = 30.0;
/// Frames a window spans (1 s), and frames between the starts of consecutive windows.
pub const WINDOW: usize = 30;
pub const HOP: usize = 15;

/// The roles whose motion a descriptor holds, in order.
pub const KEY_ROLES: [Role; 9] = [
    Role::Head,
    Role::Limb(super::body::Side::Left, Part::Elbow),
    Role::Limb(super::body::Side::Right, Part::Elbow),
    Role::Limb(super::body::Side::Left, Part::Wrist),
    Role::Limb(super::body::Side::Right, Part::Wrist),
    Role::Limb(super::body::Side::Left, Part::Knee),
    Role::Limb(super::body::Side::Right, Part::Knee),
    Role::Limb(super::body::Side::Left, Part::Ankle),
    Role::Limb(super::body::Side::Right, Part::Ankle),
];

const KEYS: usize = KEY_ROLES.len();

/// Numbers in a descriptor: per key role its mean place (3), its spread (3) and its
/// velocity's RMS (3); the pelvis's height (1) and velocity (3); the turning rate (1).
pub const DIMS: usize = KEYS * 9 + 5;

/// What each group of a descriptor is divided by: places in leg lengths, velocities in
/// leg lengths per second, turning in radians per second. The pelvis's travel and turning
/// weigh most: on the Bandai takes (`mocapstore bench --search`) they tell walking from
/// walking sideways and running, which the pose alone does not (precision@5 0.70 with
/// them at 1.5 and 1, 0.78 at 0.2); scaling every number by its spread over the corpus
/// instead gave 0.61.
pub const SCALES: Scales = Scales {
    place: 1.0,
    spread: 0.25,
    speed: 2.0,
    height: 1.0,
    root_speed: 0.2,
    turn: 0.2,
};

/// See [`SCALES`].
#[derive(Debug, Clone, Copy)]
pub struct Scales {
    pub place: f64,
    pub spread: f64,
    pub speed: f64,
    pub height: f64,
    pub root_speed: f64,
    pub turn: f64,
}

/// One window's descriptor: where it starts (a frame at [`RATE`]) and its numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    pub start: usize,
    pub descriptor: [f32; DIMS],
}

/// What a take's descriptors could be taken from.
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    pub windows: Vec<Window>,
    /// The key roles the take places (the others count as still, at the pelvis).
    pub placed: Vec<Role>,
    /// The leg length the take was scaled by (metres); `None` when its legs are not placed
    /// and its height stood in.
    pub leg_m: Option<f64>,
}

type V3 = [f64; 3];

fn at(frame: &[f32], role: usize) -> Option<V3> {
    let p = &frame[role * 3..role * 3 + 3];
    (!p.iter().any(|v| v.is_nan())).then(|| [p[0] as f64, p[1] as f64, p[2] as f64])
}

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(a: V3) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(v[v.len() / 2])
}

/// The heading of a frame: the angle about +Y of the way the body faces (0 facing +Z,
/// positive turning towards +X), from its hip and shoulder lines; `None` when neither is
/// placed.
fn heading(frame: &[f32]) -> Option<f64> {
    let mut right = [0.0, 0.0];
    let mut any = false;
    for part in [Part::Hip, Part::Shoulder] {
        let l = at(frame, Role::left(part).index());
        let r = at(frame, Role::right(part).index());
        if let (Some(l), Some(r)) = (l, r) {
            right[0] += r[0] - l[0];
            right[1] += r[2] - l[2];
            any = true;
        }
    }
    if !any || right[0].hypot(right[1]) < 1e-6 {
        return None;
    }
    // Facing = up × right: with +Y up, (x, z) of right gives (z, -x) of facing.
    let (fx, fz) = (right[1], -right[0]);
    Some(fx.atan2(fz))
}

/// Turn `v` (x, y, z) about +Y by `-heading`, into the body frame: (right, up, forward).
fn to_body(v: V3, heading: f64) -> V3 {
    let (s, c) = heading.sin_cos();
    // Forward is (s, 0, c); right is forward × up... facing +Z, right is -X.
    let forward = v[0] * s + v[2] * c;
    let right = -(v[0] * c - v[2] * s);
    [right, v[1], forward]
}

/// The windows' descriptors of a take given as one point per role ([`Role::all`]) per
/// frame (`roles`: frames × 20 × 3, metres, +Y up, at [`RATE`], NaN where a role is not
/// placed). A take shorter than a window has one window of what it has.
pub fn features(roles: &[f32]) -> Features {
    let width = Role::all().len() * 3;
    let frames: Vec<&[f32]> = roles.chunks_exact(width).collect();
    let pelvis = Role::Pelvis.index();
    let keys: Vec<usize> = KEY_ROLES.iter().map(|r| r.index()).collect();
    let placed: Vec<Role> = KEY_ROLES
        .iter()
        .zip(&keys)
        .filter(|(_, k)| frames.iter().any(|f| at(f, **k).is_some()))
        .map(|(r, _)| *r)
        .collect();
    // The leg length: hip to knee to ankle, each side, the median over frames.
    let legs: Vec<f64> = frames
        .iter()
        .flat_map(|f| {
            [super::body::Side::Left, super::body::Side::Right]
                .into_iter()
                .filter_map(|s| {
                    let h = at(f, Role::Limb(s, Part::Hip).index())?;
                    let k = at(f, Role::Limb(s, Part::Knee).index())?;
                    let a = at(f, Role::Limb(s, Part::Ankle).index())?;
                    Some(norm(sub(h, k)) + norm(sub(k, a)))
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let leg_m = median(legs).filter(|l| *l > 0.05);
    // Without legs: half the height from the head to the pelvis's floor stands in.
    let scale = leg_m.unwrap_or_else(|| {
        median(
            frames
                .iter()
                .filter_map(|f| Some(at(f, Role::Head.index())?[1] - at(f, pelvis)?[1]))
                .collect(),
        )
        .map_or(1.0, |h| (h.abs() * 1.4).max(0.1))
    });
    let floor = frames
        .iter()
        .flat_map(|f| {
            let mut lows = Vec::new();
            for r in [Role::left(Part::Ankle), Role::right(Part::Ankle)] {
                if let Some(p) = at(f, r.index()) {
                    lows.push(p[1]);
                }
            }
            lows
        })
        .fold(f64::INFINITY, f64::min);
    // Per frame: the heading (the last known one where it cannot be told), the pelvis, and
    // each key role's place in the body frame (the pelvis where it is not placed).
    let mut last_heading = 0.0;
    let mut per_frame = Vec::with_capacity(frames.len());
    for f in &frames {
        let h = heading(f).unwrap_or(last_heading);
        last_heading = h;
        let p = at(f, pelvis);
        let places: Vec<V3> = keys
            .iter()
            .map(|k| match (at(f, *k), p) {
                (Some(x), Some(p)) => {
                    let b = to_body(sub(x, p), h);
                    [b[0] / scale, b[1] / scale, b[2] / scale]
                }
                _ => [0.0; 3],
            })
            .collect();
        per_frame.push((h, p, places));
    }
    let mut windows = Vec::new();
    let n = frames.len();
    if n == 0 {
        return Features {
            windows,
            placed,
            leg_m,
        };
    }
    let mut start = 0;
    loop {
        let end = (start + WINDOW).min(n);
        windows.push(Window {
            start,
            descriptor: describe(&per_frame[start..end], scale, floor),
        });
        if end == n || start + HOP + WINDOW > n + HOP / 2 {
            break;
        }
        start += HOP;
    }
    Features {
        windows,
        placed,
        leg_m,
    }
}

type Frame = (f64, Option<V3>, Vec<V3>);

/// One window's numbers from its frames.
fn describe(frames: &[Frame], scale: f64, floor: f64) -> [f32; DIMS] {
    let s = SCALES;
    let n = frames.len() as f64;
    let mut out = [0f32; DIMS];
    for k in 0..KEYS {
        for a in 0..3 {
            let v: Vec<f64> = frames.iter().map(|f| f.2[k][a]).collect();
            let mean = v.iter().sum::<f64>() / n;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
            let speed = if frames.len() > 1 {
                let sq: f64 = v.windows(2).map(|w| ((w[1] - w[0]) * RATE).powi(2)).sum();
                (sq / (frames.len() - 1) as f64).sqrt()
            } else {
                0.0
            };
            out[k * 9 + a] = (mean / s.place) as f32;
            out[k * 9 + 3 + a] = (var.sqrt() / s.spread) as f32;
            out[k * 9 + 6 + a] = (speed / s.speed) as f32;
        }
    }
    let base = KEYS * 9;
    let heights: Vec<f64> = frames.iter().filter_map(|f| Some(f.1?[1])).collect();
    if !heights.is_empty() && floor.is_finite() {
        let h = heights.iter().sum::<f64>() / heights.len() as f64;
        out[base] = (((h - floor) / scale) / s.height) as f32;
    }
    // The pelvis's velocity in the body frame, and the turning rate, over the window.
    let (mut vel, mut turn, mut steps) = ([0.0; 3], 0.0, 0usize);
    for w in frames.windows(2) {
        if let (Some(a), Some(b)) = (w[0].1, w[1].1) {
            let d = to_body(sub(b, a), w[0].0);
            for i in 0..3 {
                vel[i] += d[i] * RATE / scale;
            }
            let mut dh = w[1].0 - w[0].0;
            while dh > std::f64::consts::PI {
                dh -= std::f64::consts::TAU;
            }
            while dh < -std::f64::consts::PI {
                dh += std::f64::consts::TAU;
            }
            turn += dh * RATE;
            steps += 1;
        }
    }
    if steps > 0 {
        for i in 0..3 {
            out[base + 1 + i] = (vel[i] / steps as f64 / s.root_speed) as f32;
        }
        out[base + 4] = (turn / steps as f64 / s.turn) as f32;
    }
    out
}

/// How much a window moves: its key roles' speeds and the pelvis's, turning included (a
/// still window has a small floor, so that a take standing still throughout still counts).
pub fn energy(d: &[f32; DIMS]) -> f64 {
    let speeds: f64 = (0..KEYS)
        .flat_map(|k| (6..9).map(move |a| k * 9 + a))
        .map(|i| f64::from(d[i]).powi(2))
        .sum();
    let root: f64 = (1..5).map(|i| f64::from(d[KEYS * 9 + i]).powi(2)).sum();
    (speeds + root).sqrt() + 0.05
}

/// A take's features with what they were taken from: its frames at [`RATE`], one point per
/// role each ([`Role::all`]), and whether its pelvis is placed.
#[derive(Debug, Clone)]
pub struct Taken {
    pub features: Features,
    pub roles: Vec<f32>,
    pub frames: usize,
    pub pelvis: bool,
}

/// The features of `m` read as the server reads a stored take's (its body from anatomy,
/// else the format's `prior`; 30 fps, metres, +Y up; one point per role): an uploaded
/// clip's, or a file's for the retrieval measure.
pub fn of_motion(m: &super::Motion, prior: Option<&super::body::Prior>) -> super::Result<Taken> {
    use super::body::{centroids, Axis, Body, Given};
    use super::transform::{whole, Options};
    let body = Body::of(m, Given::default(), prior)?;
    let shaped = whole::apply(
        m,
        &body,
        &Options {
            fps: Some(RATE),
            up: Some(Axis::Y),
            metres_per_unit: Some(1.0),
            ..Options::default()
        },
    )?;
    let names = &shaped.point_names;
    let groups = body.roles.placed_in(names);
    let roles = centroids(shaped.positions(), names.len(), &groups);
    Ok(Taken {
        features: features(&roles),
        frames: roles.len() / (Role::all().len() * 3),
        pelvis: !groups[Role::Pelvis.index()].is_empty(),
        roles,
    })
}

/// The squared Euclidean distance between two descriptors.
pub fn distance(a: &[f32; DIMS], b: &[f32; DIMS]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A figure (one point per role, metres, +Y up) walking along +Z at 1.2 m/s and facing
    /// it, its left wrist waving up and down when `wave_left`, else its right; turned about
    /// +Y by `yaw` and moved by `offset`, its sizes scaled by `size`.
    fn figure(frames: usize, wave_left: bool, yaw: f64, offset: [f64; 3], size: f64) -> Vec<f32> {
        let roles = Role::all();
        let mut out = Vec::new();
        for f in 0..frames {
            let t = f as f64 / RATE;
            for r in &roles {
                // Facing +Z, the body's left is +X.
                let mut p: [f64; 3] = match r {
                    Role::Pelvis => [0.0, 1.0, 0.0],
                    Role::Spine => [0.0, 1.2, 0.0],
                    Role::Neck => [0.0, 1.5, 0.0],
                    Role::Head => [0.0, 1.7, 0.0],
                    Role::Limb(side, part) => {
                        let x = if *side == super::super::body::Side::Left {
                            1.0
                        } else {
                            -1.0
                        };
                        let (w, h) = match part {
                            Part::Clavicle => (0.1, 1.45),
                            Part::Shoulder => (0.2, 1.45),
                            Part::Elbow => (0.25, 1.2),
                            Part::Wrist => (0.3, 0.95),
                            Part::Hip => (0.1, 0.95),
                            Part::Knee => (0.1, 0.5),
                            Part::Ankle => (0.1, 0.08),
                            Part::Toe => (0.1, 0.02),
                        };
                        let mut p = [x * w, h, 0.0];
                        let waving = (*side == super::super::body::Side::Left) == wave_left;
                        if *part == Part::Wrist && waving {
                            p[1] += 0.6 + 0.15 * (t * 6.0).sin();
                        }
                        p
                    }
                };
                p[2] += 1.2 * t;
                let (s, c) = yaw.sin_cos();
                let q = [p[0] * c + p[2] * s, p[1], -p[0] * s + p[2] * c];
                for k in 0..3 {
                    out.push(((q[k] * size) + offset[k]) as f32);
                }
            }
        }
        out
    }

    fn descriptors(roles: &[f32]) -> Vec<[f32; DIMS]> {
        features(roles)
            .windows
            .into_iter()
            .map(|w| w.descriptor)
            .collect()
    }

    #[test]
    fn where_which_way_and_how_tall_do_not_count() {
        let a = descriptors(&figure(90, true, 0.0, [0.0; 3], 1.0));
        let b = descriptors(&figure(90, true, 2.0, [3.0, 0.0, -7.0], 0.6));
        assert_eq!(a.len(), 5, "1 s windows every half second over 3 s");
        for (x, y) in a.iter().zip(&b) {
            assert!(distance(x, y) < 1e-6, "{}", distance(x, y));
        }
    }

    #[test]
    fn left_is_not_right() {
        let left = descriptors(&figure(60, true, 0.0, [0.0; 3], 1.0));
        let right = descriptors(&figure(60, false, 0.0, [0.0; 3], 1.0));
        let same = descriptors(&figure(60, true, 1.0, [1.0; 3], 1.2));
        let d = distance(&left[0], &right[0]);
        assert!(d > 1.0, "waving the left hand is not waving the right: {d}");
        assert!(distance(&left[0], &same[0]) < 1e-6);
    }

    #[test]
    fn turning_left_is_not_turning_right() {
        // Standing still, the heading turning at ±1 rad/s.
        let turning = |rate: f64| -> Vec<f32> {
            (0..30)
                .flat_map(|f| figure(1, true, rate * f as f64 / RATE, [0.0; 3], 1.0))
                .collect()
        };
        let (l, r) = (descriptors(&turning(1.0)), descriptors(&turning(-1.0)));
        let turn = KEYS * 9 + 4;
        let rate = |d: &[f32; DIMS]| f64::from(d[turn]) * SCALES.turn;
        assert!((rate(&l[0]) - 1.0).abs() < 0.01, "{}", rate(&l[0]));
        assert!((rate(&r[0]) + 1.0).abs() < 0.01, "{}", rate(&r[0]));
    }

    #[test]
    fn walking_forward_is_forward_speed() {
        let f = features(&figure(60, true, 0.7, [0.0; 3], 1.0));
        let d = &f.windows[0].descriptor;
        let base = KEYS * 9;
        let leg = f.leg_m.unwrap();
        assert!((leg - 0.87).abs() < 0.01, "{leg}");
        // Forward at 1.2 m/s, in legs per second over the scale.
        let want = 1.2 / leg / SCALES.root_speed;
        assert!(
            (d[base + 3] as f64 - want).abs() < 1e-3,
            "{} vs {want}",
            d[base + 3]
        );
        assert!(d[base + 1].abs() < 1e-3 && d[base + 2].abs() < 1e-3);
    }
}
