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

/// The axis that points up: BVH and glTF use +Y, most marker systems (and C3D) +Z. The
/// other two are horizontal; the frame stays right-handed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Up {
    Y,
    Z,
}

impl Up {
    /// The axis index (1 = y, 2 = z).
    pub fn axis(self) -> usize {
        match self {
            Up::Y => 1,
            Up::Z => 2,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Up::Y => "y",
            Up::Z => "z",
        }
    }

    /// The up axis of a figure whose points span `y` along Y and `z` along Z: the taller,
    /// Y unless Z is clearly taller (what the viewer assumes too).
    pub fn of_extents(y: f64, z: f64) -> Up {
        if z > y * 1.2 {
            Up::Z
        } else {
            Up::Y
        }
    }
}

impl fmt::Display for Up {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Up {
    type Err = String;
    fn from_str(s: &str) -> Result<Up, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "y" | "+y" => Ok(Up::Y),
            "z" | "+z" => Ok(Up::Z),
            other => Err(format!("up is y or z, not {other:?}")),
        }
    }
}

/// The up axis of frames of `points` points (`frames × points × 3`, NaN where missing):
/// of Y and Z, the axis along which the figure stands taller in the frames where it is
/// tallest (up to 32 frames looked at); `None` without two points present in a frame.
pub fn infer_up(positions: &[f32], points: usize) -> Option<Up> {
    let w = points * 3;
    if w == 0 || positions.len() < w {
        return None;
    }
    let frames = positions.len() / w;
    let step = frames.div_ceil(32).max(1);
    let (mut y, mut z) = (0.0f64, 0.0f64);
    let mut seen = false;
    for f in (0..frames).step_by(step) {
        let present: Vec<&[f32]> = positions[f * w..(f + 1) * w]
            .chunks_exact(3)
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .collect();
        if present.len() < 2 {
            continue;
        }
        seen = true;
        let extent = |axis: usize| {
            let (lo, hi) = present.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
                (lo.min(p[axis]), hi.max(p[axis]))
            });
            f64::from(hi - lo)
        };
        y = y.max(extent(1));
        z = z.max(extent(2));
    }
    seen.then(|| Up::of_extents(y, z))
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

/// What a request asks of the frames before they are written.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Options {
    /// Output frame rate; `None` keeps the take's.
    pub fps: Option<f64>,
    pub root: Root,
    /// Output up axis; `None` keeps the take's.
    pub up: Option<Up>,
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
        assert_eq!("Z".parse::<Up>().unwrap(), Up::Z);
        assert!("x".parse::<Up>().is_err());
        assert_eq!("in-place".parse::<Root>().unwrap(), Root::InPlace);
        assert!("drop".parse::<Root>().is_err());
        assert_eq!(Up::of_extents(1.7, 0.4), Up::Y);
        assert_eq!(Up::of_extents(0.4, 1.7), Up::Z);
    }

    #[test]
    fn the_taller_axis_is_up() {
        use crate::motion::synthetic::dancer;
        let m = dancer(20, 30.0, 1);
        assert_eq!(infer_up(m.positions(), m.point_count()), Some(Up::Y));
        let turned: Vec<f32> = m
            .positions()
            .chunks_exact(3)
            .flat_map(|p| [p[0], -p[2], p[1]])
            .collect();
        assert_eq!(infer_up(&turned, m.point_count()), Some(Up::Z));
        assert_eq!(infer_up(&[f32::NAN; 6], 2), None);
    }
}
