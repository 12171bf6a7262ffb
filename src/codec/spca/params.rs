//! The `spca` header block: how poses are normalised, the steps key values are stored at,
//! the residual layer's bound and every segment's model (so that a chunk, and the blend at
//! its end, needs only its own bytes and the header).

use super::model::{self, Model};
use crate::codec::entropy::{Decoder, Encoder};
use crate::codec::error::{malformed, Result};
use crate::codec::wire::{Reader, Writer};

/// The one version of the block so far.
pub const VERSION: u8 = 1;

/// `vertical` when poses are not normalised (no torso points).
const NO_TORSO: u8 = 3;

/// Everything a chunk decoder needs, parsed once.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// The vertical axis (0–2) and the torso points `[origin, left, right shoulder]`, when
    /// poses are normalised.
    pub torso: Option<(u8, [usize; 3])>,
    /// Frames at the end of a segment over which its model hands over to the next one's.
    pub blend: usize,
    /// Steps of the torso points' and the coefficients' key values, and of the models' means.
    pub torso_step: f64,
    pub coef_step: f64,
    pub mean_step: f64,
    /// Bound the residual layer enforces; 0 when there is none.
    pub residual_t: f64,
    pub models: Vec<Model>,
}

/// Model entries a header may declare per byte of its model block. An adaptive binary coder
/// can code a run of zeros in almost no bits, so a hostile header could declare millions of
/// entries in a few bytes; real means and components cost well over a bit each.
const ENTRIES_PER_BYTE: usize = 64;

impl Params {
    /// The width of the pose vectors the models code: every point but the torso's.
    pub fn pose_width(points: usize, torso: Option<(u8, [usize; 3])>) -> usize {
        3 * (points - torso.map_or(0, |_| 3))
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new();
        let (vertical, t) = self.torso.unwrap_or((NO_TORSO, [0; 3]));
        w.bytes(&[VERSION, vertical]);
        for p in t {
            w.u32(p as u32);
        }
        w.u32(self.blend as u32)
            .f64(self.torso_step)
            .f64(self.coef_step)
            .f64(self.mean_step)
            .f64(self.residual_t)
            .u32(self.models.len() as u32);
        let width = self.models.first().map_or(0, Model::width);
        let mut enc = Encoder::new();
        let mut m = model::Models::default();
        for model in &self.models {
            Model::code(&mut enc, &mut m, width, self.mean_step, Some(model))
                .expect("encoding a model it was given");
        }
        let coded = enc.finish();
        w.u32(coded.len() as u32).bytes(&coded);
        w.0
    }

    pub fn parse(bytes: &[u8], points: usize) -> Result<Params> {
        let mut r = Reader::new(bytes);
        let version = r.u8()?;
        if version != VERSION {
            return Err(malformed(format!("spca parameters of version {version}")));
        }
        let vertical = r.u8()?;
        let t = [r.u32()? as usize, r.u32()? as usize, r.u32()? as usize];
        let torso = match vertical {
            NO_TORSO => None,
            0..=2 => {
                if t.iter().any(|&p| p >= points) || t[0] == t[1] || t[0] == t[2] || t[1] == t[2] {
                    return Err(malformed(format!(
                        "spca torso points {t:?} of a take of {points} points"
                    )));
                }
                Some((vertical, t))
            }
            _ => return Err(malformed(format!("spca vertical axis {vertical}"))),
        };
        let blend = r.u32()? as usize;
        let torso_step = r.f64()?;
        let coef_step = r.f64()?;
        let mean_step = r.f64()?;
        let residual_t = r.f64()?;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let residual_ok = residual_t.is_finite() && residual_t >= 0.0;
        if !(positive(torso_step) && positive(coef_step) && positive(mean_step) && residual_ok) {
            return Err(malformed("spca steps must be positive and finite"));
        }
        let segments = r.u32()? as usize;
        let len = r.u32()? as usize;
        let coded = r.take(len)?;
        r.finish()?;
        let width = Self::pose_width(points, torso);
        if segments == 0 || width == 0 {
            return Err(malformed(format!(
                "spca header of {segments} segments of {width}-value poses"
            )));
        }
        let budget = ENTRIES_PER_BYTE * coded.len() + (1 << 16);
        let mut dec = Decoder::new(coded);
        let mut m = model::Models::default();
        let (mut models, mut entries) = (Vec::new(), 0usize);
        for _ in 0..segments {
            let model = Model::code(&mut dec, &mut m, width, mean_step, None)?;
            entries += width * (model.k() + 1);
            if entries > budget || dec.overran() {
                return Err(malformed("spca models are truncated"));
            }
            models.push(model);
        }
        Ok(Params {
            torso,
            blend,
            torso_step,
            coef_step,
            mean_step,
            residual_t,
            models,
        })
    }
}
