//! Transforms on decoded frames, between the decoder and a format's writer: another frame
//! rate ([`resample`], [`channels`]), root motion removed or kept apart, another up axis and
//! another unit ([`pose`]). Pure: the read path hands them frames a block at a time.
//!
//! Order, on every take: resample (at the source's axes and units), then root motion, then
//! axes, then unit; each is the identity when not asked for.

pub mod channels;
pub mod pose;
pub mod resample;
pub mod whole;

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

pub use crate::motion::body::Axis;
use crate::motion::Error;

/// What transforms need of a take's body ([`crate::motion::body`]): its up axis, its moving
/// root and its floor. Read from the take's stored body, never guessed from the frames.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Stance {
    /// The take's up axis; `None` when its body could not tell (then every transform that
    /// turns or moves the take over the ground is refused, naming `up=`).
    pub up: Option<Axis>,
    /// The points (a skeleton's joints) whose centroid is the pelvis: root motion follows
    /// it, whatever joint carries the translation channels. Empty: no pelvis was found.
    pub pelvis: Vec<usize>,
    /// The floor's height along `up`, in the take's units: where an extracted root motion
    /// runs. The origin's level when the body tells none, which happens only when it has
    /// no up (then nothing runs on a floor) or no point is ever present.
    pub floor: f64,
    /// The way the body faces over the take: an extracted root motion's heading is the
    /// turn from it about `up`.
    pub forward: Option<Axis>,
    /// Left and right points of the hips, then of the shoulders (those the body places):
    /// the body faces `up × (right − left)`.
    pub sides: Vec<(Vec<usize>, Vec<usize>)>,
}

impl Stance {
    /// The stance of a take whose body is `body`, whose points are `names`, in units of
    /// `metres_per_unit`.
    pub fn of(body: &crate::motion::body::Body, names: &[String], metres_per_unit: f64) -> Stance {
        use crate::motion::body::{Part, Role};
        let at = |r: Role| body.roles.points(r, names);
        Stance {
            up: body.axes.up,
            pelvis: at(Role::Pelvis),
            floor: body.axes.floor_m.map_or(0.0, |m| m / metres_per_unit),
            forward: body.axes.forward,
            sides: [Part::Hip, Part::Shoulder]
                .into_iter()
                .map(|p| (at(Role::left(p)), at(Role::right(p))))
                .filter(|(l, r)| !l.is_empty() && !r.is_empty())
                .collect(),
        }
    }

    /// The up axis, or why a transform `what` cannot be made without it (409).
    pub fn up_for(&self, what: &str) -> Result<Axis, Error> {
        self.up.ok_or_else(|| {
            Error::Unsupported(format!(
                "{what} needs the take's up axis, which its body does not tell (see the \
                 take's body.reason): give it with up= at ingest or by PATCH /v1/takes/{{id}} \
                 {{\"body\": {{\"up\": \"y\"}}}}"
            ))
        })
    }

    /// The pelvis, or why root motion cannot be moved without it (409).
    pub fn pelvis_for(&self, root: Root) -> Result<&[usize], Error> {
        if self.pelvis.is_empty() {
            return Err(Error::Unsupported(format!(
                "root={root} follows the pelvis, and no point of this take is known to be \
                 one (see the take's body.unplaced): name its pelvis by PATCH \
                 /v1/takes/{{id}} {{\"body\": {{\"roles\": {{\"pelvis\": [\"…\"]}}}}}}"
            )));
        }
        Ok(&self.pelvis)
    }
}

/// What happens to the root's motion over the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Root {
    /// As captured.
    #[default]
    Keep,
    /// The root's horizontal translation zeroed in every frame (its height kept): the take
    /// plays on the spot, every joint where it was relative to the root.
    InPlace,
    /// In place, and the horizontal translation given apart: a `root_motion` point (position
    /// formats), a `root_motion` joint above the root (BVH, glTF).
    Extract,
}

impl FromStr for Root {
    type Err = String;
    fn from_str(s: &str) -> Result<Root, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "keep" => Ok(Root::Keep),
            "in-place" | "inplace" | "in_place" => Ok(Root::InPlace),
            "extract" => Ok(Root::Extract),
            other => Err(format!("root is keep, in-place or extract, not {other:?}")),
        }
    }
}

impl fmt::Display for Root {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Root::Keep => "keep",
            Root::InPlace => "in-place",
            Root::Extract => "extract",
        })
    }
}

/// The name of the point or joint that carries an extracted root motion.
pub const ROOT_MOTION: &str = "root_motion";
/// The name of the point, half a metre ahead of [`ROOT_MOTION`] on the floor, that gives an
/// extracted root motion's heading in the position formats (a point has no rotation).
pub const ROOT_MOTION_FORWARD: &str = "root_motion_forward";
/// How far ahead of the root motion [`ROOT_MOTION_FORWARD`] lies, in metres.
pub const ROOT_MOTION_FORWARD_M: f64 = 0.5;

/// What a request asks of the frames before they are written.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Options {
    /// Output frame rate; `None` keeps the take's.
    pub fps: Option<f64>,
    pub root: Root,
    /// Output up axis; `None` keeps the take's.
    pub up: Option<Axis>,
    /// Output metres per unit; `None` keeps the take's.
    pub metres_per_unit: Option<f64>,
}

impl Options {
    /// A rate within [`crate::limits::RESAMPLE_FPS`] and a positive unit, or why not.
    pub fn check(&self) -> Result<(), String> {
        if let Some(fps) = self.fps {
            crate::limits::resample_fps(fps)?;
        }
        if let Some(m) = self.metres_per_unit {
            if !(m.is_finite() && m > 0.0) {
                return Err(format!("unit must be positive, got {m} m"));
            }
        }
        Ok(())
    }

    /// Whether nothing is asked: frames go to the writer as decoded.
    pub fn is_identity(&self) -> bool {
        *self == Options::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse() {
        assert!("drop".parse::<Root>().is_err());
        assert_eq!("in-place".parse::<Root>().unwrap(), Root::InPlace);
    }

    /// What a take's body does not tell is refused with the parameter that tells it.
    #[test]
    fn an_unknown_body_names_what_to_give() {
        let s = Stance::default();
        let e = s.up_for("glTF").unwrap_err();
        assert!(
            matches!(&e, Error::Unsupported(m) if m.contains("up=")),
            "{e}"
        );
        let e = s.pelvis_for(Root::InPlace).unwrap_err();
        assert!(
            matches!(&e, Error::Unsupported(m) if m.contains("pelvis")),
            "{e}"
        );
    }
}
