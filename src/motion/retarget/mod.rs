//! Retargeting: a skeleton take's motion put on another skeleton through the body's roles
//! ([`crate::motion::body`]), frame by frame, as channel values of the target's joints.
//!
//! [`mapping`] works out once which target joint follows which source joint and the rest
//! correction of each; [`Retarget`] applies it to each frame: every target joint that
//! follows one takes its world rotation ([`mapping`]'s formula) as its own channels in its
//! own order, every other keeps its rest rotation, and the root is moved so that the
//! target's pelvis runs the source's path scaled by their legs, its height kept above the
//! floor. Pure: channel values in, channel values out.

pub mod feet;
pub mod mapping;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

pub use mapping::{Bone, Figure, Mapping, Pair};

use feet::{Contact, Feet};

use crate::motion::body::{Part, Role};
use crate::motion::rotation::{euler_order, from_euler, to_euler};
use crate::motion::skeleton::{local_rotation, translation, Fk, Joint};
use crate::motion::Error;

/// Where a target joint's rotation is written among its channels.
#[derive(Debug, Clone)]
struct Slots {
    /// The joint's first channel in a frame.
    start: usize,
    /// Offsets (in the joint's channels) of its rotation channels, each with the place of
    /// its angle in `order`'s decomposition.
    rotations: Vec<(usize, usize)>,
    /// The Euler order the rotation is taken apart in: the joint's own axes, then those it
    /// lacks (whose angles are not written: a joint with fewer channels takes what it can).
    order: [usize; 3],
    /// Whether the joint has all three (its rotation is written exactly).
    full: bool,
}

impl Slots {
    fn of(joints: &[Joint]) -> Vec<Slots> {
        let mut start = 0;
        joints
            .iter()
            .map(|j| {
                let axes: Vec<(usize, usize)> = j
                    .channels
                    .iter()
                    .enumerate()
                    .filter_map(|(k, c)| c.rotation_axis().map(|a| (k, a)))
                    .collect();
                let (order, full) = match euler_order(&j.channels) {
                    Some(o) => (o, true),
                    None => {
                        let mut o: Vec<usize> = Vec::new();
                        for &(_, a) in &axes {
                            if !o.contains(&a) {
                                o.push(a);
                            }
                        }
                        for a in 0..3 {
                            if !o.contains(&a) {
                                o.push(a);
                            }
                        }
                        ([o[0], o[1], o[2]], false)
                    }
                };
                let mut taken = [false; 3];
                let rotations = axes
                    .iter()
                    .filter_map(|&(k, a)| {
                        let at = order.iter().position(|&x| x == a)?;
                        // An axis named twice is written once.
                        (!std::mem::replace(&mut taken[at], true)).then_some((k, at))
                    })
                    .collect();
                let s = Slots {
                    start,
                    rotations,
                    order,
                    full,
                };
                start += j.channels.len();
                s
            })
            .collect()
    }
}

/// A source skeleton's frames as a target skeleton's.
pub struct Retarget {
    mapping: Mapping,
    source: Vec<Joint>,
    target: Vec<Joint>,
    fk: Fk,
    placed: Vec<f64>,
    slots: Vec<Slots>,
    /// The target's rest: channel values, local rotations and translations.
    rest_values: Vec<f64>,
    rest_local: Vec<Matrix3<f64>>,
    rest_translation: Vec<Vector3<f64>>,
    /// The target root's position channels (indices in a frame).
    root_position: [usize; 3],
    /// The source's up coordinate and floor, and how a source unit becomes a target one
    /// along the pelvis's path (units and the legs' scale).
    source_up: usize,
    source_up_sign: f64,
    source_floor: f64,
    source_metres_per_unit: f64,
    /// The target's up axis: index and sign.
    target_up: (usize, f64),
    /// `feet=lock`'s legs, when asked ([`Retarget::lock_feet`]).
    feet: Option<Feet>,
    path_scale: f64,
    /// Each target joint's last written angles (continuity across ±180°).
    last: Vec<Option<[f64; 3]>>,
    world: Vec<Matrix3<f64>>,
    places: Vec<Vector3<f64>>,
}

impl Retarget {
    /// Frames of `source` as frames of `target`. Refused when the map cannot be made
    /// ([`Mapping::new`]) or the target's root has no three position channels to carry
    /// the path.
    pub fn new(source: &Figure, target: &Figure) -> Result<Retarget, Error> {
        let mapping = Mapping::new(source, target)?;
        let root = target
            .joints
            .first()
            .ok_or_else(|| Error::Unsupported("the target skeleton has no joints".into()))?;
        let pos = |axis: usize| root.channels.iter().position(|c| c.axis() == (axis, false));
        let root_position = match (pos(0), pos(1), pos(2)) {
            (Some(x), Some(y), Some(z)) => [x, y, z],
            _ => {
                return Err(Error::Unsupported(format!(
                    "the target skeleton's root {:?} has no three position channels to carry \
                     the take's path",
                    root.name
                )))
            }
        };
        let slots = Slots::of(target.joints);
        let mut rest_local = Vec::with_capacity(target.joints.len());
        let mut rest_translation = Vec::with_capacity(target.joints.len());
        for (j, s) in target.joints.iter().zip(&slots) {
            let vals = &target.rest[s.start..s.start + j.channels.len()];
            rest_local.push(local_rotation(j, vals));
            rest_translation.push(Vector3::from(translation(j, vals)));
        }
        let n = target.joints.len();
        Ok(Retarget {
            source: source.joints.to_vec(),
            target: target.joints.to_vec(),
            fk: Fk::new(source.joints),
            placed: vec![0.0; source.joints.len() * 3],
            slots,
            rest_values: target.rest.clone(),
            rest_local,
            rest_translation,
            root_position,
            source_up: source.up.index(),
            source_up_sign: source.up.sign(),
            source_floor: source.floor,
            source_metres_per_unit: source.metres_per_unit,
            target_up: (target.up.index(), target.up.sign()),
            feet: None,
            path_scale: source.metres_per_unit * mapping.scale / target.metres_per_unit,
            mapping,
            last: vec![None; n],
            world: vec![Matrix3::identity(); n],
            places: vec![Vector3::zeros(); n],
        })
    }

    pub fn mapping(&self) -> &Mapping {
        &self.mapping
    }

    /// The skeleton frames are written for.
    pub fn joints(&self) -> &[Joint] {
        &self.target
    }

    /// Channels a source frame has.
    pub fn channels_in(&self) -> usize {
        self.source.iter().map(|j| j.channels.len()).sum()
    }

    /// Channels a written frame has.
    pub fn channels_out(&self) -> usize {
        self.rest_values.len()
    }

    /// One source frame's channel values, appended to `out` as the target's.
    pub fn frame(&mut self, src: &[f64], out: &mut Vec<f64>) {
        self.fk.frame(&self.source, src, &mut self.placed);
        let at = out.len();
        out.extend_from_slice(&self.rest_values);
        let vals = &mut out[at..];
        let g = self.mapping.turn();
        let source_world = self.fk.rotations();
        for i in 0..self.target.len() {
            let joint = &self.target[i];
            let slots = &self.slots[i];
            let (parent_world, parent_place) = match joint.parent {
                Some(p) => (self.world[p], self.places[p]),
                None => (Matrix3::identity(), Vector3::zeros()),
            };
            let driven = self
                .mapping
                .pair_of(i)
                .filter(|_| !slots.rotations.is_empty())
                .map(|p| {
                    let w = g * source_world[p.source] * p.k;
                    match p.aim {
                        None => w,
                        Some(aim) => {
                            let at = |j: usize| {
                                Vector3::new(
                                    self.placed[j * 3],
                                    self.placed[j * 3 + 1],
                                    self.placed[j * 3 + 2],
                                )
                            };
                            let want = g * (at(aim.to) - at(aim.from));
                            let now = w * aim.local;
                            if want.norm() > 0.0 {
                                mapping::least_turn(&now, &want.normalize()).into_inner() * w
                            } else {
                                w
                            }
                        }
                    }
                });
            let local = match driven {
                None => self.rest_local[i],
                Some(world) => write(
                    slots,
                    &mut self.last[i],
                    parent_world.transpose() * world,
                    vals,
                ),
            };
            self.world[i] = parent_world * local;
            self.places[i] = parent_place + parent_world * self.rest_translation[i];
        }
        // The pelvis onto the source's, scaled, its height above the floor kept.
        let (ps, pt) = self.mapping.pelvis;
        let mut v = Vector3::new(
            self.placed[ps * 3],
            self.placed[ps * 3 + 1],
            self.placed[ps * 3 + 2],
        );
        // The floor is a height along up: its coordinate is signed as up is.
        v[self.source_up] -= self.source_floor * self.source_up_sign;
        let want = g * (v * self.path_scale);
        let shift = want - self.places[pt];
        for (a, &c) in self.root_position.iter().enumerate() {
            vals[self.slots[0].start + c] += shift[a];
        }
        if let Some(feet) = &mut self.feet {
            for p in &mut self.places {
                *p += shift;
            }
            let target = &self.target;
            let (lowered, turned) = feet.frame(&self.placed, &mut self.places, &self.world, &|j| {
                target[j].parent
            });
            for (a, &c) in self.root_position.iter().enumerate() {
                vals[self.slots[0].start + c] += lowered[a];
            }
            for t in turned {
                self.world[t.joint] = t.world;
                let parent = target[t.joint]
                    .parent
                    .map_or_else(Matrix3::identity, |p| self.world[p]);
                write(
                    &self.slots[t.joint],
                    &mut self.last[t.joint],
                    parent.transpose() * t.world,
                    vals,
                );
            }
        }
    }

    /// Hold the target's feet still while the source's stand on the floor (`feet=lock`,
    /// [`feet`]), the source running at `fps`. Legs whose hip, knee and ankle are not a chain
    /// of joints with three rotation channels each are left as they are.
    pub fn lock_feet(&mut self, fps: f64) {
        let m = &self.mapping;
        let role = |r: Role, source: bool| {
            m.pairs
                .iter()
                .find(|p| p.role == Some(r))
                .map(|p| if source { p.source } else { p.target })
        };
        let target = &self.target;
        let slots = &self.slots;
        let chained = |r: Role| {
            let j = role(r, false)?;
            let Role::Limb(side, part) = r else {
                return Some(j);
            };
            let ok = slots[j].full
                && match part {
                    Part::Knee => target[j].parent == role(Role::Limb(side, Part::Hip), false),
                    Part::Ankle => target[j].parent == role(Role::Limb(side, Part::Knee), false),
                    _ => true,
                };
            ok.then_some(j)
        };
        let (up, sign) = (self.source_up, self.source_up_sign);
        let (floor, mpu) = (self.source_floor, self.source_metres_per_unit);
        let bone = |r: Role| role(r, false).map_or(0.0, |j| Vector3::from(target[j].offset).norm());
        let legs: Vec<f64> = crate::motion::body::Side::BOTH
            .into_iter()
            .map(|s| bone(Role::Limb(s, Part::Knee)) + bone(Role::Limb(s, Part::Ankle)))
            .filter(|l| *l > 0.0)
            .collect();
        let legs_length = legs.iter().sum::<f64>() / legs.len().max(1) as f64;
        self.feet = Some(Feet::new(
            &chained,
            &|r| role(r, true),
            &|points| Contact::new(points, (up, sign), floor, mpu, fps),
            self.target_up,
            legs_length,
            fps,
        ));
    }
}

/// Joint `slots`' channels written (into the frame's `vals`) for the rotation `local`
/// relative to its parent, continuous with `last`; the rotation they hold (a joint with
/// fewer than three rotation channels holds what they can, and its children make up the
/// rest).
fn write(
    slots: &Slots,
    last: &mut Option<[f64; 3]>,
    local: Matrix3<f64>,
    vals: &mut [f64],
) -> Matrix3<f64> {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(local));
    let e = if slots.full {
        to_euler(&q, slots.order, *last)
    } else {
        // The channels it has hold only part of the turn: the other of the two Euler
        // solutions would write another rotation, so the first is kept, each angle only
        // turned by whole turns toward the last frame's.
        let mut e = to_euler(&q, slots.order, None);
        if let Some(l) = last {
            for (v, l) in e.iter_mut().zip(l.iter()) {
                *v += 360.0 * ((*l - *v) / 360.0).round();
            }
        }
        e
    };
    if e.iter().all(|v| v.is_finite()) {
        *last = Some(e);
    }
    for &(k, a) in &slots.rotations {
        vals[slots.start + k] = e[a];
    }
    if slots.full {
        return local;
    }
    let mut kept = [0.0; 3];
    for &(_, a) in &slots.rotations {
        kept[a] = e[a];
    }
    from_euler(slots.order, kept)
        .to_rotation_matrix()
        .into_inner()
}

#[cfg(test)]
mod tests;
