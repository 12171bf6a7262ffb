//! The map from one skeleton to another, worked out once from their rest poses: which
//! target joint follows which source joint (by the body's roles), the rest-pose correction
//! of each, and the scale of the root's path.
//!
//! # The correction
//! A target joint `i` that plays the role source joint `j` plays takes, in every frame, the
//! world rotation `W_T = G · W_S · K` with `K = P⁻¹ · A · Q`: `P` and `Q` are the two
//! joints' world rotations in their rest poses, `G` turns the source's world to the
//! target's (their up axes), and `A` turns the target's rest to the source's rest where the
//! joint's bones point. The bones from a joint are the segments to the next joints that play
//! roles below it (hip to knee, chest to neck and to both clavicles), so zero-length joints
//! (CMU's `LHipJoint`) and spines of other lengths are bridged. Each rest pose is first put in
//! a body frame of its own (left, up, forward, from its hips, shoulders and spine), so the
//! two rests are compared as bodies whatever their world axes: a T-pose and an A-pose differ
//! by the 40° at the shoulder, not by how their files lie.
//!
//! `A` is the rotation that takes the target's rest bones onto the source's: the least
//! rotation for a joint with one bone, after its parent's correction (so an arm's twist
//! follows the shoulder's); the best fit of all its bones for a joint with several (the
//! pelvis, the chest); the parent's correction for a joint with no bone (a wrist with no
//! mapped hand), so a hand goes on along its forearm.

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

use crate::motion::body::{Part, Role, Roles, Side};
use crate::motion::skeleton::{Fk, Joint};
use crate::motion::transform::Axis;
use crate::motion::Error;

/// A skeleton as retargeting sees it: its joints, the pose they rest in, which joints play
/// which role, and the world they are in.
#[derive(Debug, Clone)]
pub struct Figure<'a> {
    pub joints: &'a [Joint],
    /// Channel values of the rest pose ([`crate::motion::skeleton::rest_values`] for a BVH
    /// rig; a character's bind pose for one read from glTF or FBX).
    pub rest: Vec<f64>,
    pub roles: &'a Roles,
    /// The world's up axis (the take's body's; +Y for a standard rig).
    pub up: Axis,
    /// The floor's coordinate along `up`, in the figure's units (0 for a rig, which stands
    /// on its origin's level): the root's height is kept above it.
    pub floor: f64,
    pub metres_per_unit: f64,
}

/// One target joint driven by a source joint.
#[derive(Debug, Clone)]
pub struct Pair {
    /// The role both joints play; `None` for joints paired by name below a paired one
    /// (fingers, twist joints: [`by_name`]).
    pub role: Option<Role>,
    pub target: usize,
    pub source: usize,
    /// `A` in the body frame: how far the source's rest bones lie from the target's.
    pub correction: Rotation3<f64>,
    /// Whether the joint was fitted by its trunk bone and its sides ([`trunk_fit`]): then
    /// its bones out to the sides keep the target's own shape.
    pub trunk: bool,
    /// `K = P⁻¹ · A · Q` ([the module's](self) formula).
    pub(super) k: Matrix3<f64>,
    /// The bone the joint is aimed along in every frame, after `K`: where joints between it
    /// and the next one move in the source but not in the target (CMU's `Neck1` between its
    /// neck and head), the rest correction alone would leave the bone off by their turn.
    pub(super) aim: Option<Aim>,
}

/// A bone to aim: its direction in the target joint's own frame, and the source joints
/// whose places give where it should point.
#[derive(Debug, Clone, Copy)]
pub(super) struct Aim {
    pub local: Vector3<f64>,
    pub from: usize,
    pub to: usize,
}

impl Pair {
    /// The rest-pose correction's angle, degrees.
    pub fn correction_degrees(&self) -> f64 {
        // Through the quaternion: the matrix's trace can pass 3 by rounding, and its acos
        // would be NaN.
        nalgebra::UnitQuaternion::from_rotation_matrix(&self.correction)
            .angle()
            .to_degrees()
    }
}

/// The map of a source skeleton onto a target one.
#[derive(Debug, Clone)]
pub struct Mapping {
    /// Target joints that follow a source joint, parents first.
    pub pairs: Vec<Pair>,
    /// For each target joint, its pair (an index into `pairs`).
    pub(super) of_target: Vec<Option<usize>>,
    /// Target joints (not end sites) that follow none and keep their rest rotation.
    pub unmapped: Vec<usize>,
    /// Source joints (not end sites) no target joint follows.
    pub unused: Vec<usize>,
    /// Roles the target has and the source does not (its joints keep their rest).
    pub missing: Vec<Role>,
    /// Target metres per source metre: the ratio of their legs (hip to knee to ankle), or
    /// of their trunks (pelvis to head) when either has no legs.
    pub scale: f64,
    /// The source's pelvis joint and the target's: the root's path follows them.
    pub pelvis: (usize, usize),
    /// `G`: the source's world to the target's (a turn between their up axes).
    pub(super) g: Matrix3<f64>,
}

impl Mapping {
    /// The map of `source` onto `target` through their roles. Refused (`Unsupported`,
    /// saying what is missing) when either has no pelvis or its rest pose is not a body
    /// whose up and sides can be told.
    pub fn new(source: &Figure, target: &Figure) -> Result<Mapping, Error> {
        let s_roles = role_joints(source);
        let t_roles = role_joints(target);
        let mut pairs_by_target: Vec<Option<(Option<Role>, usize)>> =
            vec![None; target.joints.len()];
        let mut missing = Vec::new();
        for role in Role::all() {
            let (Some(t), Some(s)) = (t_roles.get(role), s_roles.get(role)) else {
                if t_roles.get(role).is_some() {
                    missing.push(role);
                }
                continue;
            };
            for (ti, si) in chain_pairs(t, s) {
                pairs_by_target[ti] = Some((Some(role), si));
            }
        }
        by_name(source.joints, target.joints, &mut pairs_by_target);
        let pelvis = match (s_roles.one(Role::Pelvis), t_roles.one(Role::Pelvis)) {
            (Some(s), Some(t)) => (s, t),
            _ => {
                return Err(Error::Unsupported(
                    "retargeting moves the target's pelvis along the source's, and one of \
                     the two skeletons has no joint known to be its pelvis (a take's is named \
                     by PATCH /v1/takes/ID {\"body\": {\"roles\": {\"pelvis\": [\"…\"]}}})"
                        .into(),
                ))
            }
        };
        let s_rest = Rest::of(source)?;
        let t_rest = Rest::of(target)?;
        let r_s = s_rest.body_frame(&s_roles, "source")?;
        let r_t = t_rest.body_frame(&t_roles, "target")?;

        let mapped_t: Vec<bool> = pairs_by_target.iter().map(Option::is_some).collect();
        let mut mapped_s = vec![false; source.joints.len()];
        for (_, s) in pairs_by_target.iter().flatten() {
            mapped_s[*s] = true;
        }
        let mut pairs: Vec<Pair> = Vec::new();
        let mut of_target: Vec<Option<usize>> = vec![None; target.joints.len()];
        // Each mapped target joint's correction, for its mapped descendants.
        let mut m_of: Vec<Option<Rotation3<f64>>> = vec![None; target.joints.len()];
        for ti in 0..target.joints.len() {
            let Some((role, si)) = pairs_by_target[ti] else {
                continue;
            };
            let m_parent = mapped_ancestor(target.joints, &pairs_by_target, ti)
                .and_then(|a| m_of[a])
                .unwrap_or_else(Rotation3::identity);
            // The bones: to each mapped target joint whose nearest mapped ancestor is this
            // one, and to the source joint it follows, where that lies below this one's.
            let mut bones: Vec<(Vector3<f64>, Vector3<f64>)> = Vec::new();
            let mut kinds: Vec<Option<Role>> = Vec::new();
            let mut aims: Vec<Option<Aim>> = Vec::new();
            for (ci, pair) in pairs_by_target.iter().enumerate() {
                let Some((child_role, sc)) = *pair else {
                    continue;
                };
                if ci == ti
                    || mapped_ancestor(target.joints, &pairs_by_target, ci) != Some(ti)
                    || !descends(source.joints, sc, si)
                {
                    continue;
                }
                // A bone of no length (CMU's LowerBack starts where its Hips are) points
                // along the one after it.
                let (v_t, _) = t_rest.reach(target.joints, &mapped_t, ti, ci);
                let (v_s, s_end) = s_rest.reach(source.joints, &mapped_s, si, sc);
                let (u_t, u_s) = (r_t * v_t, r_s * v_s);
                if u_t.norm() > t_rest.tiny && u_s.norm() > s_rest.tiny {
                    bones.push((u_t.normalize(), u_s.normalize()));
                    kinds.push(child_role);
                    // A bone reached through the next one (of no length in the source) is
                    // not aimed: that one's own turn would tilt this joint.
                    aims.push((s_end == sc).then(|| Aim {
                        local: (t_rest.rotation(ti).transpose() * v_t).normalize(),
                        from: si,
                        to: sc,
                    }));
                }
            }
            let trunk = (bones.len() > 1)
                .then(|| trunk_fit(&bones, &kinds))
                .flatten();
            let m = match (bones.len(), trunk) {
                (_, Some(m)) => m,
                (0, _) => m_parent,
                (1, _) => least_turn(&(m_parent * bones[0].0), &bones[0].1) * m_parent,
                _ => best_fit(&bones),
            };
            let aim = match (bones.len(), trunk) {
                (1, _) => aims[0],
                (_, Some(_)) => kinds
                    .iter()
                    .position(|r| matches!(r, Some(Role::Spine | Role::Neck | Role::Head)))
                    .and_then(|i| aims[i]),
                _ => None,
            };
            m_of[ti] = Some(m);
            // A in the rests' worlds, then K = P⁻¹ · A · Q.
            let a = r_s.transpose() * m.matrix() * r_t;
            let k = s_rest.rotation(si).transpose() * a * t_rest.rotation(ti);
            of_target[ti] = Some(pairs.len());
            pairs.push(Pair {
                role,
                target: ti,
                source: si,
                correction: m,
                trunk: trunk.is_some(),
                k,
                aim,
            });
        }
        let used: Vec<usize> = pairs.iter().map(|p| p.source).collect();
        let unmapped = (0..target.joints.len())
            .filter(|&i| of_target[i].is_none() && !target.joints[i].end_site)
            .collect();
        let unused = (0..source.joints.len())
            .filter(|i| !used.contains(i) && !source.joints[*i].end_site)
            .collect();
        let scale = match (
            s_rest.leg(&s_roles, source.metres_per_unit),
            t_rest.leg(&t_roles, target.metres_per_unit),
        ) {
            (Some(s), Some(t)) => t / s,
            _ => match (
                s_rest.trunk(&s_roles, source.metres_per_unit),
                t_rest.trunk(&t_roles, target.metres_per_unit),
            ) {
                (Some(s), Some(t)) => t / s,
                _ => 1.0,
            },
        };
        let g = source
            .up
            .turn_to(target.up)
            .unwrap_or_else(Matrix3::identity);
        Ok(Mapping {
            pairs,
            of_target,
            unmapped,
            unused,
            missing,
            scale,
            pelvis,
            g,
        })
    }

    /// The pair target joint `i` follows, if any.
    pub fn pair_of(&self, i: usize) -> Option<&Pair> {
        self.of_target[i].map(|p| &self.pairs[p])
    }

    /// `G`, the turn from the source's world to the target's.
    pub fn turn(&self) -> &Matrix3<f64> {
        &self.g
    }

    /// The mapped bones: each pair whose target joint has a mapped ancestor, from that
    /// ancestor's pair to this one. What the target draws from the one to the other points
    /// where the source's does, except a trunk joint's bones out to the sides
    /// ([`Bone::shape`]).
    pub fn bones(&self, target: &[Joint]) -> Vec<Bone> {
        (0..self.pairs.len())
            .filter_map(|c| {
                let a = mapped_ancestor(target, &self.of_target, self.pairs[c].target)?;
                let from = self.of_target[a]?;
                Some(Bone {
                    from,
                    to: c,
                    shape: self.pairs[from].trunk
                        && matches!(self.pairs[c].role, Some(Role::Limb(..))),
                })
            })
            .collect()
    }
}

/// A bone between two pairs (indices into [`Mapping::pairs`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bone {
    pub from: usize,
    pub to: usize,
    /// A bone whose direction is the target's own shape: from a trunk joint out to a side
    /// (the pelvis to a hip, the chest to a clavicle), turned with the trunk. SMPL's hips
    /// lie 9 cm below its pelvis joint, Mixamo's 5 cm: no rotation of the pelvis points
    /// both rigs' hip bones alike, and the legs below them do not depend on it.
    pub shape: bool,
}

/// Which joints of a figure play each role: one joint, or the spine's chain, parents first.
#[derive(Debug, Default)]
struct RoleJoints(std::collections::BTreeMap<Role, Vec<usize>>);

impl RoleJoints {
    fn get(&self, r: Role) -> Option<&[usize]> {
        self.0.get(&r).map(Vec::as_slice).filter(|v| !v.is_empty())
    }

    fn one(&self, r: Role) -> Option<usize> {
        self.get(r).map(|v| v[0])
    }
}

fn role_joints(f: &Figure) -> RoleJoints {
    let names: Vec<String> = f.joints.iter().map(|j| j.name.clone()).collect();
    let mut out = RoleJoints::default();
    for role in Role::all() {
        let mut at = f.roles.points(role, &names);
        // Joints are parents first: the chain's order is its indices'.
        at.sort_unstable();
        at.dedup();
        if role != Role::Spine {
            at.truncate(1);
        }
        if !at.is_empty() {
            out.0.insert(role, at);
        }
    }
    out
}

/// Target and source joints paired along a role's chains (`t`, `s`, parents first): the
/// ends with the ends, joints between spread evenly, each source joint once (a longer
/// target chain leaves some of its joints to follow their parent).
fn chain_pairs(t: &[usize], s: &[usize]) -> Vec<(usize, usize)> {
    let (m, n) = (t.len(), s.len());
    if m == 1 {
        // One joint for the whole chain: it carries what is above it (the chest).
        return vec![(t[0], s[n - 1])];
    }
    let mut out = Vec::new();
    let mut used = Vec::new();
    for k in (0..m).rev() {
        let at = ((k * (n - 1)) as f64 / (m - 1) as f64).round() as usize;
        if !used.contains(&at) {
            used.push(at);
            out.push((t[k], s[at]));
        }
    }
    out.reverse();
    out
}

/// Pair, by name, target joints no role pairs with source joints no role pairs: a joint
/// that is not an end site, named alike once namespaces, case and separators are set
/// aside (`mixamorig:LeftHandIndex1` and `LeftHandIndex1`), below the source joint its own
/// nearest paired ancestor follows. Fingers and twist joints, which no role names, follow
/// so when both rigs have them; parents first, so a finger's chain pairs joint by joint.
fn by_name(source: &[Joint], target: &[Joint], pairs: &mut [Option<(Option<Role>, usize)>]) {
    use crate::motion::body::names::normalise;
    let mut used: Vec<bool> = vec![false; source.len()];
    for (_, s) in pairs.iter().flatten() {
        used[*s] = true;
    }
    let names: Vec<String> = source.iter().map(|j| normalise(&j.name)).collect();
    for ti in 0..target.len() {
        if pairs[ti].is_some() || target[ti].end_site || target[ti].channels.is_empty() {
            continue;
        }
        let Some(anchor) = mapped_ancestor(target, pairs, ti).and_then(|a| pairs[a]) else {
            continue;
        };
        let want = normalise(&target[ti].name);
        let found = (0..source.len()).find(|&si| {
            !used[si] && !source[si].end_site && names[si] == want && descends(source, si, anchor.1)
        });
        if let Some(si) = found {
            used[si] = true;
            pairs[ti] = Some((None, si));
        }
    }
}

/// The nearest proper ancestor of `i` that follows a source joint.
fn mapped_ancestor<T>(joints: &[Joint], mapped: &[Option<T>], i: usize) -> Option<usize> {
    let mut at = joints[i].parent;
    while let Some(a) = at {
        if mapped[a].is_some() {
            return Some(a);
        }
        at = joints[a].parent;
    }
    None
}

/// Whether `j` lies below `ancestor` (strictly).
fn descends(joints: &[Joint], j: usize, ancestor: usize) -> bool {
    let mut at = joints[j].parent;
    while let Some(a) = at {
        if a == ancestor {
            return true;
        }
        at = joints[a].parent;
    }
    false
}

/// The least rotation taking unit `a` to unit `b`; a half turn about an axis across both
/// when they are opposite.
pub(super) fn least_turn(a: &Vector3<f64>, b: &Vector3<f64>) -> Rotation3<f64> {
    let c = a.cross(b);
    let (sin, cos) = (c.norm(), a.dot(b));
    if sin > 1e-12 {
        return Rotation3::from_axis_angle(&Unit::new_unchecked(c / sin), sin.atan2(cos));
    }
    if cos > 0.0 {
        return Rotation3::identity();
    }
    let across = if a.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    Rotation3::from_axis_angle(&Unit::new_normalize(a.cross(&across)), std::f64::consts::PI)
}

/// For a joint whose bones go up the trunk and out to both sides (the pelvis to the spine
/// and the hips, the chest to the neck and the clavicles): the rotation that takes the
/// trunk's bone exactly onto the source's and the line from the right child to the left
/// one as near as it can. The rigs' shapes differ most in how far below the pelvis the hips
/// lie and how high the clavicles start; the trunk's direction is what the motion shows.
/// `None` when the bones are not of that kind.
fn trunk_fit(
    bones: &[(Vector3<f64>, Vector3<f64>)],
    kinds: &[Option<Role>],
) -> Option<Rotation3<f64>> {
    let find = |f: &dyn Fn(&Option<Role>) -> bool| kinds.iter().position(f).map(|i| bones[i]);
    let trunk = find(&|r| matches!(r, Some(Role::Spine | Role::Neck | Role::Head)))?;
    let left = find(&|r| matches!(r, Some(Role::Limb(Side::Left, _))))?;
    let right = find(&|r| matches!(r, Some(Role::Limb(Side::Right, _))))?;
    let frame = |up: Vector3<f64>, across: Vector3<f64>| -> Option<Matrix3<f64>> {
        let a = across - up * up.dot(&across);
        (a.norm() > 1e-6).then(|| {
            let a = a.normalize();
            Matrix3::from_columns(&[up, a, up.cross(&a)])
        })
    };
    let t = frame(trunk.0, left.0 - right.0)?;
    let s = frame(trunk.1, left.1 - right.1)?;
    Some(Rotation3::from_matrix_unchecked(s * t.transpose()))
}

/// The rotation that best takes each first vector onto its second (Kabsch: the SVD of
/// their correlation, its determinant kept positive).
fn best_fit(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Rotation3<f64> {
    let mut h = Matrix3::zeros();
    for (a, b) in pairs {
        h += b * a.transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Rotation3::identity();
    };
    let d = (u * v_t).determinant().signum();
    let m = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
    Rotation3::from_matrix_unchecked(m)
}

/// A figure's rest pose: each joint's place and world rotation.
struct Rest {
    places: Vec<Vector3<f64>>,
    rotations: Vec<Matrix3<f64>>,
    /// A length below which a bone is taken as none (a millionth of the figure's size).
    tiny: f64,
}

impl Rest {
    fn of(f: &Figure) -> Result<Rest, Error> {
        let channels: usize = f.joints.iter().map(|j| j.channels.len()).sum();
        if f.rest.len() != channels {
            return Err(Error::Contradiction(format!(
                "a rest pose of {} values for {channels} channels",
                f.rest.len()
            )));
        }
        let mut fk = Fk::new(f.joints);
        let mut out = vec![0.0; f.joints.len() * 3];
        fk.frame(f.joints, &f.rest, &mut out);
        let places: Vec<Vector3<f64>> = out
            .chunks_exact(3)
            .map(|p| Vector3::new(p[0], p[1], p[2]))
            .collect();
        let size = places
            .iter()
            .map(|p| (p - places[0]).norm())
            .fold(0.0, f64::max);
        Ok(Rest {
            places,
            rotations: fk.rotations().to_vec(),
            tiny: size * 1e-6,
        })
    }

    /// From joint `from` to `to`, or on to the first joint below `to` in `marked` when `to`
    /// stands where `from` does; and the joint it reaches.
    fn reach(
        &self,
        joints: &[Joint],
        marked: &[bool],
        from: usize,
        to: usize,
    ) -> (Vector3<f64>, usize) {
        let d = self.place(to) - self.place(from);
        if d.norm() > self.tiny {
            return (d, to);
        }
        (to + 1..joints.len())
            .find(|&j| marked[j] && descends(joints, j, to))
            .map_or((d, to), |j| (self.place(j) - self.place(from), j))
    }

    fn place(&self, i: usize) -> Vector3<f64> {
        self.places[i]
    }

    fn rotation(&self, i: usize) -> Matrix3<f64> {
        self.rotations[i]
    }

    /// The rotation from the rest's world to its body frame (rows: left, up, forward): up
    /// from the pelvis to the head (or neck, or the spine's top), left from the right hip
    /// and shoulder to the left ones.
    fn body_frame(&self, roles: &RoleJoints, which: &str) -> Result<Matrix3<f64>, Error> {
        let pelvis = roles.one(Role::Pelvis).expect("checked by the caller");
        let top = [Role::Head, Role::Neck]
            .into_iter()
            .find_map(|r| roles.one(r))
            .or_else(|| roles.get(Role::Spine).map(|s| s[s.len() - 1]));
        let up = top.map(|t| self.place(t) - self.place(pelvis));
        let mut across = Vector3::zeros();
        for part in [Part::Hip, Part::Shoulder] {
            if let (Some(l), Some(r)) = (
                roles.one(Role::Limb(Side::Left, part)),
                roles.one(Role::Limb(Side::Right, part)),
            ) {
                let d = self.place(l) - self.place(r);
                if d.norm() > self.tiny {
                    across += d.normalize();
                }
            }
        }
        let refused = || {
            Error::Unsupported(format!(
                "the {which} skeleton's rest pose does not tell its up and sides (it needs a \
                 pelvis, a head, neck or spine above it, and left and right hips or \
                 shoulders)"
            ))
        };
        let up = up.filter(|u| u.norm() > self.tiny).ok_or_else(refused)?;
        let u = up.normalize();
        let l = across - u * u.dot(&across);
        if l.norm() < 1e-3 * across.norm().max(self.tiny) || across.norm() <= self.tiny {
            return Err(refused());
        }
        let l = l.normalize();
        let f = l.cross(&u);
        Ok(Matrix3::from_rows(&[
            l.transpose(),
            u.transpose(),
            f.transpose(),
        ]))
    }

    /// The mean length (metres) of the legs, hip to knee to ankle, of the sides that have them.
    fn leg(&self, roles: &RoleJoints, metres_per_unit: f64) -> Option<f64> {
        let lengths: Vec<f64> = Side::BOTH
            .into_iter()
            .filter_map(|s| {
                let at = |p| roles.one(Role::Limb(s, p)).map(|j| self.place(j));
                let (h, k, a) = (at(Part::Hip)?, at(Part::Knee)?, at(Part::Ankle)?);
                Some(((k - h).norm() + (a - k).norm()) * metres_per_unit)
            })
            .filter(|l| *l > 0.0)
            .collect();
        (!lengths.is_empty()).then(|| lengths.iter().sum::<f64>() / lengths.len() as f64)
    }

    /// The pelvis to head (or neck) distance, metres.
    fn trunk(&self, roles: &RoleJoints, metres_per_unit: f64) -> Option<f64> {
        let p = self.place(roles.one(Role::Pelvis)?);
        let t = [Role::Head, Role::Neck]
            .into_iter()
            .find_map(|r| roles.one(r))?;
        Some((self.place(t) - p).norm() * metres_per_unit).filter(|l| *l > 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chains_pair_their_ends_and_spread_the_rest() {
        assert_eq!(chain_pairs(&[1], &[5, 6, 7]), vec![(1, 7)]);
        assert_eq!(chain_pairs(&[1, 2], &[5, 6, 7]), vec![(1, 5), (2, 7)]);
        assert_eq!(chain_pairs(&[1, 2, 3], &[5, 6]), vec![(1, 5), (3, 6)]);
        assert_eq!(
            chain_pairs(&[1, 2, 3], &[5, 6, 7]),
            vec![(1, 5), (2, 6), (3, 7)]
        );
    }

    #[test]
    fn fits_take_bones_onto_bones() {
        let r = Rotation3::from_axis_angle(&Vector3::y_axis(), 0.7)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), -0.3);
        let a = [Vector3::x(), Vector3::new(0.0, 1.0, 1.0).normalize()];
        let pairs: Vec<_> = a.iter().map(|v| (*v, r * v)).collect();
        let fit = best_fit(&pairs);
        assert!((fit.matrix() - r.matrix()).norm() < 1e-9, "{fit} vs {r}");
        let t = least_turn(&Vector3::x(), &-Vector3::x());
        assert!((t * Vector3::x() + Vector3::x()).norm() < 1e-12);
        let t = least_turn(&Vector3::y(), &Vector3::z());
        assert!((t * Vector3::y() - Vector3::z()).norm() < 1e-12);
        assert!((t * Vector3::x() - Vector3::x()).norm() < 1e-12, "no twist");
    }
}
