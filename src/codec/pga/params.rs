//! A `pga` take's header parameters: how it was coded and the model it was coded with.
//!
//! Version 2, 3 and 4 (1 had no model kind byte, [`Geodesics::parse_v1`]; 3's chunks end
//! with their Euler branch changes, 4's also twist near gimbal lock), little-endian: `version u8`, `iterations u8` (IK steps per frame, at most
//! [`MAX_ITERATIONS`]; 0: poses from the coordinates alone, end points not coded),
//! `stride u8` (log₂ of the lifting's coarsest stride, at most [`MAX_STRIDE_LOG2`]),
//! `base f64` (the `α` of step index 224, take units), `rho f32`, `lambda f32`
//! ([`Scale`](super::scale::Scale)), `root u32` (the joint coded from, [`Layout`]),
//! `constants u32` then per channel that holds still `channel u32, value f64`
//! ([`Layout::constants`]), then the model ([`Geodesics::to_bytes`]) to the end.

use super::layout::Layout;
use super::model::Geodesics;
use crate::codec::error::{malformed, Result};
use crate::codec::skeleton::Skeleton;
use crate::codec::wire::{Reader, Writer};

/// What the encoder writes. Version 2 added the model's kind byte (the canonical model);
/// version 1 models are all fitted ([`Geodesics::parse_v1`]). Version 3 has the same
/// header, and each chunk ends with its Euler branch changes
/// ([`branches`](crate::codec::branches)); version 4's chunks say whether their decoded
/// triples are [`twisted`](crate::codec::twists) near gimbal lock, before the branch changes.
pub const VERSION: u8 = 4;
/// The versions a decoder reads.
pub const VERSIONS: [u8; 4] = [1, 2, 3, 4];
/// IK steps per decoded frame: what bounds a chunk's decoding time.
pub const MAX_ITERATIONS: u8 = 8;
/// The lifting's coarsest stride, 2⁸ frames at most.
pub const MAX_STRIDE_LOG2: u8 = 8;

#[derive(Debug, Clone)]
pub struct Params {
    /// The version the take was written with ([`VERSIONS`]).
    pub version: u8,
    pub iterations: u8,
    pub stride_log2: u8,
    pub base: f64,
    pub rho: f64,
    pub lambda: f64,
    pub root: usize,
    pub constants: Vec<(usize, f64)>,
    pub model: Geodesics,
    /// The model as stored: [`Geodesics::parse`] of these gives `model`.
    pub model_bytes: Vec<u8>,
}

impl Params {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.bytes(&[self.version, self.iterations, self.stride_log2])
            .f64(self.base)
            .f32(self.rho as f32)
            .f32(self.lambda as f32)
            .u32(self.root as u32)
            .u32(self.constants.len() as u32);
        for &(i, v) in &self.constants {
            w.u32(i as u32).f64(v);
        }
        w.bytes(&self.model_bytes);
        w.0
    }

    /// The parameters of a take of `rig`, and its layout; `rho` and `lambda` come back as
    /// the f32 they were stored as.
    pub fn parse(bytes: &[u8], rig: &Skeleton) -> Result<(Params, Layout)> {
        let channels = rig.channel_count();
        let mut r = Reader::named(bytes, "pga parameters");
        let version = r.u8()?;
        if !VERSIONS.contains(&version) {
            return Err(malformed(format!("pga version {version}")));
        }
        let iterations = r.u8()?;
        let stride_log2 = r.u8()?;
        if iterations > MAX_ITERATIONS || stride_log2 > MAX_STRIDE_LOG2 {
            return Err(malformed(format!(
                "pga with {iterations} IK steps and stride 2^{stride_log2}"
            )));
        }
        let base = r.f64()?;
        let rho = f64::from(r.f32()?);
        let lambda = f64::from(r.f32()?);
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(base) && positive(rho) && lambda.is_finite() && lambda >= 0.0) {
            return Err(malformed(format!(
                "pga steps: base {base}, rho {rho}, lambda {lambda}"
            )));
        }
        let root = r.u32()? as usize;
        let count = r.u32()? as usize;
        if count > channels {
            return Err(malformed(format!(
                "{count} constant channels in a rig of {channels}"
            )));
        }
        let mut constants = Vec::with_capacity(count);
        for _ in 0..count {
            constants.push((r.u32()? as usize, r.f64()?));
        }
        let layout = Layout::with_constants(rig, root, &constants)
            .map_err(|e| malformed(format!("pga parameters: {e}")))?;
        let inner = layout.inner_count();
        let at = r.position();
        let model_bytes = bytes[at..].to_vec();
        let model = match version {
            // Takes written between the canonical model's arrival and this version's say
            // version 1 with a kind byte: read so when the layout without it does not parse
            // (the two cannot both consume the model's bytes exactly).
            1 => Geodesics::parse_v1(&model_bytes, inner, 3 * inner).or_else(|first| {
                Geodesics::parse(&model_bytes, inner, 3 * inner).map_err(|_| first)
            })?,
            _ => Geodesics::parse(&model_bytes, inner, 3 * inner)?,
        };
        let params = Params {
            version,
            iterations,
            stride_log2,
            base,
            rho,
            lambda,
            root,
            constants,
            model,
            model_bytes,
        };
        Ok((params, layout))
    }
}
