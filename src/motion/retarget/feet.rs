//! `feet=lock`: a retargeted foot held still while the source's foot is on the floor.
//!
//! Legs of other proportions than the source's slide: the pelvis runs the source's path
//! scaled by the legs, but each foot's place comes from the angles, and the two agree only
//! where the proportions do. So contacts are read from the source (a foot's lowest point
//! near the floor and slow over it), the target's ankle is held where it was when the
//! contact began (across the floor; its height stays the pose's, so a heel still lifts),
//! and a two-bone pass on hip and knee reaches it, the foot keeping its turn in the world.
//! When the contact ends the hold is let go over [`RELEASE_S`].

use nalgebra::{Matrix3, Vector3};

use super::mapping::least_turn;
use crate::motion::body::{Part, Role, Side};

/// How near the floor (metres) a foot's lowest point must be to stand on it: an ankle
/// stands about 8 cm above it, a toe joint 2 to 5 cm.
pub const CONTACT_HEIGHT_M: f64 = 0.12;
/// How slowly (metres a second, across the floor) it must move: a foot in swing moves at
/// 1 to 5 m/s, one rolling over its toes at well under this.
pub const CONTACT_SPEED_M_S: f64 = 0.5;
/// How long a released hold takes to fade, seconds.
pub const RELEASE_S: f64 = 0.15;

/// Contacts of one foot, read frame after frame from the source.
#[derive(Debug, Clone)]
pub struct Contact {
    /// The source's joints whose lowest one is the foot's (its ankle and toe).
    points: Vec<usize>,
    up: usize,
    sign: f64,
    /// The floor's coordinate along up, source units.
    floor: f64,
    metres_per_unit: f64,
    fps: f64,
    last: Option<Vector3<f64>>,
}

impl Contact {
    /// The contacts of the foot whose joints are `points`, in a source of `up` (index and
    /// sign), whose floor lies at `floor` along it, in `metres_per_unit`, at `fps`.
    pub fn new(
        points: Vec<usize>,
        (up, sign): (usize, f64),
        floor: f64,
        metres_per_unit: f64,
        fps: f64,
    ) -> Contact {
        Contact {
            points,
            up,
            sign,
            floor,
            metres_per_unit,
            fps,
            last: None,
        }
    }

    /// Whether the foot stands on the floor in the frame whose joints are at `placed`
    /// (`joints × 3`, source units); the first frame is judged by its height alone.
    pub fn step(&mut self, placed: &[f64]) -> bool {
        let at = |j: usize| Vector3::new(placed[j * 3], placed[j * 3 + 1], placed[j * 3 + 2]);
        let Some(lowest) = self
            .points
            .iter()
            .map(|&j| at(j))
            .min_by(|a, b| (a[self.up] * self.sign).total_cmp(&(b[self.up] * self.sign)))
        else {
            return false;
        };
        // The floor is a height along up (the coordinate times up's sign).
        let height = (lowest[self.up] * self.sign - self.floor) * self.metres_per_unit;
        let speed = self.last.map_or(0.0, |l| {
            let mut d = lowest - l;
            d[self.up] = 0.0;
            d.norm() * self.metres_per_unit * self.fps
        });
        self.last = Some(lowest);
        height < CONTACT_HEIGHT_M && speed < CONTACT_SPEED_M_S
    }
}

/// One target leg and its hold.
#[derive(Debug, Clone)]
struct Leg {
    hip: usize,
    knee: usize,
    ankle: usize,
    contact: Contact,
    /// Where the ankle is held across the floor, while the source's foot stands.
    held: Option<Vector3<f64>>,
    /// A released hold: the offset still applied and the frames it fades over.
    fading: Option<(Vector3<f64>, usize, usize)>,
}

/// The legs a target holds, with what they need of both skeletons.
#[derive(Debug, Clone)]
pub struct Feet {
    legs: Vec<Leg>,
    /// The target's up axis: its index (a hold is across it) and its direction.
    up: usize,
    up_vector: Vector3<f64>,
    /// The mean length of the held legs (hip to knee to ankle), target units.
    legs_length: f64,
    release: usize,
}

/// A target joint's new world rotation, from a leg's pass.
pub struct Turned {
    pub joint: usize,
    pub world: Matrix3<f64>,
}

impl Feet {
    /// The legs of the target whose joints play `target_role` (hip, knee and ankle on each
    /// side: a side without them is not held), read from the source's ankle and toe
    /// (`source_role`).
    pub fn new(
        target_role: &dyn Fn(Role) -> Option<usize>,
        source_role: &dyn Fn(Role) -> Option<usize>,
        contact: &dyn Fn(Vec<usize>) -> Contact,
        target_up: (usize, f64),
        legs_length: f64,
        fps: f64,
    ) -> Feet {
        let legs = Side::BOTH
            .into_iter()
            .filter_map(|s| {
                let t = |p| target_role(Role::Limb(s, p));
                let (hip, knee, ankle) = (t(Part::Hip)?, t(Part::Knee)?, t(Part::Ankle)?);
                let points: Vec<usize> = [Part::Ankle, Part::Toe]
                    .into_iter()
                    .filter_map(|p| source_role(Role::Limb(s, p)))
                    .collect();
                (!points.is_empty()).then(|| Leg {
                    hip,
                    knee,
                    ankle,
                    contact: contact(points),
                    held: None,
                    fading: None,
                })
            })
            .collect();
        let mut up_vector = Vector3::zeros();
        up_vector[target_up.0] = target_up.1;
        Feet {
            legs,
            up: target_up.0,
            up_vector,
            legs_length,
            release: (RELEASE_S * fps).round().max(1.0) as usize,
        }
    }

    /// One frame: the source's joints at `placed` tell the contacts; the target's joints
    /// stand at `places` with world rotations `world` (its parents in `parent`). Where a
    /// held ankle lies beyond its leg's reach, the whole body is lowered until it does not
    /// (`places` moved with it; the move is returned, for the root's channels). Each held
    /// leg's hip and knee are then turned to reach the hold; what turned is returned too
    /// (the hip's and knee's world rotations, the ankle's unchanged), to be written.
    pub fn frame(
        &mut self,
        placed: &[f64],
        places: &mut [Vector3<f64>],
        world: &[Matrix3<f64>],
        parent: &dyn Fn(usize) -> Option<usize>,
    ) -> (Vector3<f64>, Vec<Turned>) {
        let mut wants = Vec::with_capacity(self.legs.len());
        for leg in &mut self.legs {
            let standing = leg.contact.step(placed);
            let free = places[leg.ankle];
            let mut want = free;
            match (standing, leg.held) {
                (true, None) => leg.held = Some(free),
                (true, Some(h)) => {
                    for a in 0..3 {
                        if a != self.up {
                            want[a] = h[a];
                        }
                    }
                }
                (false, Some(h)) => {
                    let mut off = h - free;
                    off[self.up] = 0.0;
                    leg.fading = Some((off, self.release, self.release));
                    leg.held = None;
                }
                (false, None) => {}
            }
            if !standing {
                if let Some((off, left, all)) = leg.fading {
                    want = free + off * (left as f64 / (all + 1) as f64);
                    leg.fading = (left > 1).then_some((off, left - 1, all));
                }
            }
            wants.push(want - free);
        }
        // Lower the body where a hold is out of reach: the hip comes down along up until
        // the ankle's hold lies within the leg's length.
        let u = self.up_vector;
        let mut drop = 0.0f64;
        for (leg, off) in self.legs.iter().zip(&wants) {
            if off.norm() == 0.0 {
                continue;
            }
            let hip = places[leg.hip];
            let reach =
                (places[leg.knee] - hip).norm() + (places[leg.ankle] - places[leg.knee]).norm();
            let h = hip - (places[leg.ankle] + off);
            let length = reach * (1.0 - 1e-6);
            if h.norm() <= length {
                continue;
            }
            let along = h.dot(&u);
            let inside = along * along - (h.norm_squared() - length * length);
            if inside >= 0.0 {
                drop = drop.max(along - inside.sqrt());
            }
        }
        let shift = -u * drop.min(MOST_DROP * self.legs_length);
        if drop > 0.0 {
            for p in places.iter_mut() {
                *p += shift;
            }
        }
        let mut out = Vec::new();
        for (leg, off) in self.legs.iter().zip(&wants) {
            if off.norm() > 0.0 {
                let want = places[leg.ankle] - shift + off;
                out.extend(reach(leg, want, places, world, parent));
            }
        }
        (shift, out)
    }
}

/// How far (a share of the legs' length) the body is lowered at most to reach a hold.
const MOST_DROP: f64 = 0.15;

/// Hip and knee of `leg` turned so that its ankle reaches `want` (or as near as the leg's
/// length allows), bending in the plane the knee bends in now.
fn reach(
    leg: &Leg,
    want: Vector3<f64>,
    places: &[Vector3<f64>],
    world: &[Matrix3<f64>],
    parent: &dyn Fn(usize) -> Option<usize>,
) -> Vec<Turned> {
    let (a_at, b_at, c_at) = (places[leg.hip], places[leg.knee], places[leg.ankle]);
    let (a, b) = ((b_at - a_at).norm(), (c_at - b_at).norm());
    let to = want - a_at;
    if a <= 0.0 || b <= 0.0 || to.norm() <= 0.0 || parent(leg.ankle) != Some(leg.knee) {
        return Vec::new();
    }
    let d = to.norm().clamp((a - b).abs() + 1e-9, a + b - 1e-9);
    let u = to / to.norm();
    let bend = {
        let k = b_at - a_at;
        let n = k - u * u.dot(&k);
        if n.norm() > 1e-9 * a {
            n.normalize()
        } else {
            // A straight leg: bend it forward of the hip's own frame.
            let f = world[leg.hip] * Vector3::z();
            (f - u * u.dot(&f)).try_normalize(1e-12).unwrap_or_else(|| {
                let x = Vector3::x();
                (x - u * u.dot(&x)).normalize()
            })
        }
    };
    let cos = ((a * a + d * d - b * b) / (2.0 * a * d)).clamp(-1.0, 1.0);
    let knee = a_at + a * (cos * u + (1.0 - cos * cos).sqrt() * bend);
    let ankle = a_at + d * u;
    let r1 = least_turn(&((b_at - a_at) / a), &((knee - a_at) / a)).into_inner();
    let hip_world = r1 * world[leg.hip];
    let shin_now = r1 * (c_at - b_at) / b;
    let r2 = least_turn(&shin_now, &((ankle - knee) / b)).into_inner();
    let knee_world = r2 * r1 * world[leg.knee];
    vec![
        Turned {
            joint: leg.hip,
            world: hip_world,
        },
        Turned {
            joint: leg.knee,
            world: knee_world,
        },
        Turned {
            joint: leg.ankle,
            world: world[leg.ankle],
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Thigh and shin of 0.4 m each, hip at 1 m, knee bent forward: the ankle reaches a point
    /// within reach exactly, keeping the bone lengths; out of reach it stretches toward it.
    #[test]
    fn two_bones_reach_the_hold() {
        let places = vec![
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(0.0, 0.6, 0.05),
            Vector3::new(0.0, 0.2, 0.0),
        ];
        let world = vec![Matrix3::identity(); 3];
        let leg = Leg {
            hip: 0,
            knee: 1,
            ankle: 2,
            contact: Contact::new(vec![2], (1, 1.0), 0.0, 1.0, 30.0),
            held: None,
            fading: None,
        };
        let parent = |j: usize| j.checked_sub(1);
        let want = Vector3::new(0.1, 0.3, 0.1);
        let t = reach(&leg, want, &places, &world, &parent);
        // The ankle, as the turned hip and knee place it.
        let thigh = places[1] - places[0];
        let shin = places[2] - places[1];
        let knee = places[0] + t[0].world * thigh;
        let ankle = knee + t[1].world * shin;
        assert!((ankle - want).norm() < 1e-9, "{ankle}");
        // Bent forward (+z), as it was.
        assert!(knee.z > 0.0);
        let far = Vector3::new(0.0, -1.0, 0.0);
        let t = reach(&leg, far, &places, &world, &parent);
        let knee = places[0] + t[0].world * thigh;
        let ankle = knee + t[1].world * shin;
        let length = thigh.norm() + shin.norm();
        assert!(
            (ankle - Vector3::new(0.0, 1.0 - length, 0.0)).norm() < 1e-6,
            "{ankle}"
        );
    }

    /// A foot low and still stands; high or fast, it does not.
    #[test]
    fn contacts_are_low_and_slow() {
        let mut c = Contact::new(vec![0], (1, 1.0), 0.0, 0.01, 100.0);
        assert!(c.step(&[0.0, 5.0, 0.0])); // 5 cm up, first frame
        assert!(c.step(&[0.2, 5.0, 0.0])); // 0.2 m/s
        assert!(!c.step(&[1.2, 5.0, 0.0])); // 1 m/s
        assert!(!c.step(&[1.2, 30.0, 0.0])); // 30 cm up
    }
}
