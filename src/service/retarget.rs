//! `skeleton=`: the skeleton an answer puts a take's motion on. A standard rig shipped with
//! the service ([`crate::motion::rigs`]), a stored skeleton, or the skeleton of another
//! take, resolved once per request into a [`Target`]; the math is
//! [`crate::motion::retarget`].

use std::str::FromStr;
use std::sync::Arc;

use super::access::{check_take, Grant};
use super::prepared::Prepared;
use super::{Error, Result};
use crate::motion::body::{Axes, Body, Roles};
use crate::motion::retarget::{Figure, Retarget};
use crate::motion::rigs;
use crate::motion::skeleton::{rest_places, rest_values, Joint};
use crate::motion::transform::{Axis, Stance};
use crate::store::Store;

/// What `skeleton=` names. (`openapi.yaml`'s pattern for `skeleton=` and `to=` lists the
/// standard rigs' names: a rig added to [`rigs::all`] is added there.)
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Onto {
    /// A standard rig, by name (`mixamo`, `smpl`).
    Rig(&'static str),
    /// A stored skeleton, by id (`GET /v1/skeletons`).
    Skeleton(String),
    /// The skeleton of a stored take (`take:ID`), with that take's roles and axes.
    Take(String),
}

impl FromStr for Onto {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Onto, String> {
        let s = s.trim();
        if let Some(id) = s.strip_prefix("take:") {
            if id.is_empty() {
                return Err("skeleton=take: needs a take id after the colon".into());
            }
            return Ok(Onto::Take(id.to_string()));
        }
        if let Some(rig) = rigs::all()
            .into_iter()
            .find(|r| r.name.eq_ignore_ascii_case(s))
        {
            return Ok(Onto::Rig(rig.name));
        }
        if !s.is_empty() && s.len() <= 128 && s.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Ok(Onto::Skeleton(s.to_ascii_lowercase()));
        }
        let names: Vec<&str> = rigs::all().iter().map(|r| r.name).collect();
        Err(format!(
            "skeleton={s:?} is not a standard rig ({}), a stored skeleton's id (GET \
             /v1/skeletons) or take:ID",
            names.join(", ")
        ))
    }
}

/// Whether a take put on another skeleton can be written as `format`: a skeleton format
/// (BVH, glTF, FBX) holds the target's joints and channels, a position format (JSON, CSV,
/// TRC, NPY, f32) its joints' places; C3D keeps the lab's markers and is a 400, told
/// before the skeleton is looked for.
pub fn check_format(format: crate::motion::format::Format) -> Result<()> {
    use crate::motion::format::Format;
    if format != Format::C3d {
        return Ok(());
    }
    Err(Error::InvalidRequest(
        "skeleton= puts the take on another skeleton, and C3D keeps the lab's markers: ask \
         for bvh, glb, gltf or fbx (the skeleton), or json, csv, trc, npy or f32 (its \
         joints' places)"
            .into(),
    ))
}

/// The indices of joints `want` among `names` (a target's): a 400 naming the first that
/// is not one of them, or that is named twice.
pub fn joint_indices(names: &[String], want: &[String]) -> Result<Vec<usize>> {
    let mut seen = std::collections::HashSet::new();
    want.iter()
        .map(|w| {
            if !seen.insert(w.as_str()) {
                return Err(Error::InvalidRequest(format!(
                    "point {w:?} is named more than once in points"
                )));
            }
            names.iter().position(|n| n == w).ok_or_else(|| {
                let shown: Vec<&str> = names.iter().take(20).map(String::as_str).collect();
                Error::InvalidRequest(format!(
                    "no joint named {w:?} in the target skeleton; its {} joints include {}",
                    names.len(),
                    shown.join(", ")
                ))
            })
        })
        .collect()
}

/// What `feet=` asks of a retargeted take's feet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Feet {
    /// As the angles place them.
    #[default]
    Free,
    /// Held still while the source's feet stand on the floor
    /// ([`crate::motion::retarget::feet`]).
    Lock,
}

impl FromStr for Feet {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Feet, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "free" => Ok(Feet::Free),
            "lock" => Ok(Feet::Lock),
            other => Err(format!("feet is free or lock, not {other:?}")),
        }
    }
}

/// A skeleton to put takes on, with what retargeting needs of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// What the request named (`mixamo`, a skeleton id, `take:ID`).
    pub name: String,
    pub joints: Vec<Joint>,
    pub roles: Roles,
    /// Its world's up: the take's body's, +Y for a standard rig, and for a stored skeleton
    /// the axis its rest pose stands along (BVH's +Y when its rest is no standing body).
    pub up: Axis,
    pub metres_per_unit: f64,
    /// Channel values of its rest pose: an uploaded character's bind pose, else its
    /// offsets' (rotations zero).
    pub rest: Vec<f64>,
    /// The id of the uploaded skeleton whose character file it skins: a GLB or glTF answer
    /// is that file playing the take ([`crate::motion::formats::gltf::character`]), loaded
    /// only for them ([`super::skeletons::character`]).
    pub character: Option<String>,
}

impl Target {
    /// The figure retargeting maps onto (standing on its origin's level).
    pub fn figure(&self) -> Figure<'_> {
        Figure {
            joints: &self.joints,
            rest: self.rest.clone(),
            roles: &self.roles,
            up: self.up,
            floor: 0.0,
            metres_per_unit: self.metres_per_unit,
        }
    }
}

/// The target `onto` names, as `grant` may see it (another take's or a stored skeleton
/// outside its libraries is not found).
pub async fn target(store: &Store, grant: &Grant, onto: &Onto) -> Result<Arc<Target>> {
    Ok(Arc::new(match onto {
        Onto::Rig(name) => {
            let rig = rigs::named(name).ok_or_else(|| Error::NotFound(format!("rig {name}")))?;
            Target {
                name: rig.name.to_string(),
                roles: Roles::of_skeleton(&rig.joints),
                rest: rest_values(&rig.joints),
                joints: rig.joints,
                up: Axis::Y,
                metres_per_unit: 1.0,
                character: None,
            }
        }
        Onto::Skeleton(id) => {
            let (row, rig) = super::skeletons::get(store, id, grant).await?;
            let joints = rig.joints().to_vec();
            let rest = rig.rest();
            let roles = super::skeletons::roles(&rig);
            let character = rig.character().map(|_| row.id.clone());
            Target {
                name: row.id,
                up: standing_up(&joints, &rest, &roles),
                // A glTF character is in metres by its format; any other rig's unit is
                // read from its height.
                metres_per_unit: if character.is_some() {
                    1.0
                } else {
                    unit_of(&joints, &rest)
                },
                roles,
                joints,
                rest,
                character,
            }
        }
        Onto::Take(id) => {
            check_take(store, grant, id).await?;
            let take = super::fetch::take(store, id).await?;
            let skeleton = take.skeleton.clone().ok_or_else(|| {
                Error::Unsatisfiable(format!(
                    "take {id} is point data: it has no skeleton to put motion on"
                ))
            })?;
            let body = take.body().ok_or_else(|| {
                Error::Unsatisfiable(format!(
                    "take {id}'s body is not derived yet; retry shortly"
                ))
            })?;
            let up = body.axes.up.ok_or_else(|| {
                Error::Unsatisfiable(format!(
                    "take {id}'s body does not tell its up axis: give it by PATCH \
                     /v1/takes/{id} {{\"body\": {{\"up\": \"y\"}}}}"
                ))
            })?;
            let rig = super::skeletons::load(store, &skeleton).await?;
            Target {
                name: format!("take:{id}"),
                joints: rig.joints().to_vec(),
                roles: body.roles,
                up,
                metres_per_unit: take.metres_per_unit,
                rest: rig.rest(),
                character: None,
            }
        }
    }))
}

/// A stored skeleton's unit (it keeps none; its takes do), from its rest pose's height as
/// a take's is inferred; metres when that tells nothing.
fn unit_of(joints: &[Joint], rest: &[f64]) -> f64 {
    let at = rest_at(joints, rest);
    // As a take's rest height: Y or Z (a T-pose is as wide as it is tall, so X never).
    let height = (1..3)
        .map(|c| {
            let (lo, hi) = at
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p[c]), hi.max(p[c]))
                });
            hi - lo
        })
        .fold(0.0, f64::max);
    crate::motion::units::Unit::infer_from_height(height).map_or(1.0, |u| u.metres_per_unit)
}

/// Where a skeleton's joints stand in its rest pose (`rest`: its channel values), file
/// units.
fn rest_at(joints: &[Joint], rest: &[f64]) -> Vec<[f64; 3]> {
    let fk = crate::motion::skeleton::Animation {
        joints: joints.to_vec(),
        values: rest.to_vec(),
        printed: None,
    }
    .forward_kinematics();
    if fk.len() != joints.len() * 3 {
        return rest_places(joints);
    }
    fk.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect()
}

/// How a stored skeleton maps onto a target, as `GET /v1/skeletons/{id}/map` shows it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MapView {
    /// The stored skeleton and what the target was named.
    pub from: String,
    pub to: String,
    /// Target metres per source metre: the path's scale (the legs' ratio).
    pub scale: f64,
    /// Each target joint that follows a source joint, target parents first.
    pub joints: Vec<JointMap>,
    /// Target joints that follow none and keep their rest rotation.
    pub unmapped: Vec<String>,
    /// Source joints no target joint follows (their turn reaches the target only through
    /// the next mapped joint's aim).
    pub unused: Vec<String>,
    /// Roles the target has and the source does not.
    pub missing_roles: Vec<String>,
    /// Target bones whose direction is the target's own shape (from a trunk joint out to a
    /// side): turned with the trunk, not aimed along the source's.
    pub shape_bones: Vec<ShapeBone>,
}

/// One target joint and the source joint it follows.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct JointMap {
    pub joint: String,
    pub follows: String,
    /// The role both play; `null` for joints paired by name (fingers, twist joints).
    pub role: Option<String>,
    /// How far the two rest poses' bones lie apart at this joint (the rest correction's
    /// angle), degrees: 40 at the shoulder between a T-pose and an A-pose.
    pub correction_degrees: f64,
}

/// A rig-shape bone of the target.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ShapeBone {
    pub from: String,
    pub to: String,
}

/// How stored skeleton `id` maps onto `onto`, as `grant` may see both.
pub async fn map(store: &Store, grant: &Grant, id: &str, onto: &Onto) -> Result<MapView> {
    let (row, rig) = super::skeletons::get(store, id, grant).await?;
    let target = target(store, grant, onto).await?;
    let joints = rig.joints().to_vec();
    let roles = super::skeletons::roles(&rig);
    let rest = rig.rest();
    let source = Figure {
        joints: &joints,
        up: standing_up(&joints, &rest, &roles),
        metres_per_unit: unit_of(&joints, &rest),
        rest,
        roles: &roles,
        floor: 0.0,
    };
    let m =
        crate::motion::retarget::Mapping::new(&source, &target.figure()).map_err(|e| match e {
            crate::motion::Error::Contradiction(m) => Error::Corrupt(m),
            other => Error::Unsatisfiable(other.to_string()),
        })?;
    let (s, t) = (&joints, &target.joints);
    Ok(MapView {
        from: row.id,
        to: target.name.clone(),
        scale: m.scale,
        joints: m
            .pairs
            .iter()
            .map(|p| JointMap {
                joint: t[p.target].name.clone(),
                follows: s[p.source].name.clone(),
                role: p.role.map(|r| r.name()),
                correction_degrees: p.correction_degrees(),
            })
            .collect(),
        unmapped: m.unmapped.iter().map(|&i| t[i].name.clone()).collect(),
        unused: m.unused.iter().map(|&i| s[i].name.clone()).collect(),
        missing_roles: m.missing.iter().map(|r| r.name()).collect(),
        shape_bones: m
            .bones(t)
            .into_iter()
            .filter(|b| b.shape)
            .map(|b| ShapeBone {
                from: t[m.pairs[b.from].target].name.clone(),
                to: t[m.pairs[b.to].target].name.clone(),
            })
            .collect(),
    })
}

/// The axis a skeleton's rest pose stands along (pelvis below head within 30° of it), or
/// BVH's +Y when the rest is no standing body (Bandai's rest lays every bone along x).
fn standing_up(joints: &[Joint], rest: &[f64], roles: &Roles) -> Axis {
    use crate::motion::body::Role;
    let names: Vec<String> = joints.iter().map(|j| j.name.clone()).collect();
    let at = rest_at(joints, rest);
    let one = |r: Role| roles.points(r, &names).first().map(|&i| at[i]);
    let (Some(p), Some(h)) = (one(Role::Pelvis), one(Role::Head).or(one(Role::Neck))) else {
        return Axis::Y;
    };
    let v = nalgebra::Vector3::new(h[0] - p[0], h[1] - p[1], h[2] - p[2]);
    match Axis::nearest(&v) {
        Some(a) if v.norm() > 0.0 && a.vector().dot(&v) / v.norm() > 30f64.to_radians().cos() => a,
        _ => Axis::Y,
    }
}

/// The retargeter of a take's skeleton (`joints`, its stored body's roles and axes, its
/// frames at `fps`) onto `target`, its feet as `feet` asks, and the stance of the frames it writes (the target's pelvis, up and sides;
/// the take's forward turned to the target's world), for the transforms after it.
pub fn retargeter(
    prepared: &Prepared,
    joints: &[Joint],
    target: &Target,
    feet: Feet,
    fps: f64,
) -> Result<(Retarget, Stance)> {
    let body = prepared.body.as_ref().ok_or_else(|| {
        Error::Unsatisfiable(format!(
            "take {}'s body is not derived yet; retry shortly",
            prepared.id
        ))
    })?;
    let up = prepared
        .stance
        .up_for("skeleton=")
        .map_err(|e| Error::Unsatisfiable(e.to_string()))?;
    let source = Figure {
        joints,
        rest: rest_values(joints),
        roles: &body.roles,
        up,
        floor: prepared.stance.floor,
        metres_per_unit: prepared.metres_per_unit,
    };
    let mut r = Retarget::new(&source, &target.figure()).map_err(|e| match e {
        crate::motion::Error::Unsupported(m) => Error::Unsatisfiable(m),
        crate::motion::Error::Contradiction(m) => Error::Corrupt(m),
        other => Error::Unsatisfiable(other.to_string()),
    })?;
    if feet == Feet::Lock {
        r.lock_feet(fps);
    }
    let forward = prepared
        .stance
        .forward
        .and_then(|f| Axis::nearest(&(r.mapping().turn() * f.vector())));
    let names: Vec<String> = target.joints.iter().map(|j| j.name.clone()).collect();
    let written = Body {
        axes: Axes {
            up: Some(target.up),
            forward,
            floor_m: Some(0.0),
            up_from: None,
            forward_from: None,
            reason: String::new(),
        },
        roles: target.roles.clone(),
    };
    let stance = Stance::of(&written, &names, target.metres_per_unit);
    Ok((r, stance))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse() {
        assert_eq!("mixamo".parse::<Onto>().unwrap(), Onto::Rig("mixamo"));
        assert_eq!("SMPL".parse::<Onto>().unwrap(), Onto::Rig("smpl"));
        assert_eq!(
            "take:0192f0c1-aa".parse::<Onto>().unwrap(),
            Onto::Take("0192f0c1-aa".into())
        );
        assert_eq!(
            "ABCDEF0123".parse::<Onto>().unwrap(),
            Onto::Skeleton("abcdef0123".into())
        );
        let e = "unreal".parse::<Onto>().unwrap_err();
        assert!(e.contains("mixamo, smpl") && e.contains("take:ID"), "{e}");
        assert!("take:".parse::<Onto>().is_err());
    }

    #[test]
    fn a_standard_rig_stands_along_y() {
        for rig in rigs::all() {
            assert_eq!(
                standing_up(
                    &rig.joints,
                    &rest_values(&rig.joints),
                    &Roles::of_skeleton(&rig.joints)
                ),
                Axis::Y
            );
        }
    }
}
