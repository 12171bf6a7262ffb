//! One chunk — one segment — written once for both directions: its key frames
//! ([`Coder::code`]) and the frames they decode to ([`Coder::reconstruct`]). The encoder's
//! trials measure exactly what a decoder will give.
//!
//! A chunk holds its segment's index, the torso points' keys, its model's coefficient keys
//! and, unless it is the last, the next segment's coefficient keys over its last
//! [`Params::blend`] frames: over those frames the two models' poses are blended (the weight
//! of the next rising smoothly from 0 to 1), so the hand-over has no jump, and the chunk still
//! decodes from its own bytes and the header.

use super::params::Params;
use super::spline::{self, Keys};
use super::torso::{placement, to_world, Placement};
use crate::codec::entropy::io::Io;
use crate::codec::error::{malformed, Result};

/// Key-value contexts of the coefficient trajectories: by component index on a log scale
/// (leading components swing widest).
const COEF_CONTEXTS: usize = 6;

fn coef_context(j: usize) -> usize {
    ((usize::BITS - j.leading_zeros()) as usize).min(COEF_CONTEXTS - 1)
}

/// A chunk's keys, as coded.
#[derive(Debug, Clone, PartialEq)]
pub struct ChunkKeys {
    pub segment: usize,
    /// The torso points' nine coordinates (none without normalisation).
    pub torso: Vec<Keys>,
    /// The segment model's coefficients, one trajectory per component.
    pub coefs: Vec<Keys>,
    /// The next segment model's coefficients over the blend (none for the last segment).
    pub lead: Vec<Keys>,
}

/// Codes and decodes chunks of one take.
pub struct Coder {
    pub params: Params,
    pub points: usize,
    /// The points the models code (all but the torso's), in order.
    pub posed: Vec<usize>,
}

impl Coder {
    pub fn new(params: Params, points: usize) -> Coder {
        let torso = params.torso.map(|(_, t)| t);
        let posed = (0..points)
            .filter(|p| torso.is_none_or(|t| !t.contains(p)))
            .collect();
        Coder {
            params,
            points,
            posed,
        }
    }

    /// Frames at the end of a chunk of segment `segment` (of `frames` frames) that blend into
    /// the next segment's model.
    pub fn lead_frames(&self, segment: usize, frames: usize) -> usize {
        if segment + 1 < self.params.models.len() {
            self.params.blend.min(frames)
        } else {
            0
        }
    }

    /// Code one chunk of `frames` frames through `io` (`given` when encoding).
    pub fn code<I: Io>(
        &self,
        io: &mut I,
        frames: usize,
        given: Option<&ChunkKeys>,
    ) -> Result<ChunkKeys> {
        let segment = io.raw(given.map_or(0, |g| g.segment as u32), 32) as usize;
        let model = self.params.models.get(segment).ok_or_else(|| {
            malformed(format!(
                "spca chunk of segment {segment}; the take has {}",
                self.params.models.len()
            ))
        })?;
        let mut trajectories = |count: usize,
                                n: usize,
                                given: Option<&[Keys]>,
                                models: &mut [spline::Models],
                                context: &dyn Fn(usize) -> usize| {
            (0..count)
                .map(|j| spline::code(io, &mut models[context(j)], n, given.map(|g| &g[j])))
                .collect::<Vec<Keys>>()
        };
        let torso = if self.params.torso.is_some() {
            let mut m = vec![spline::Models::default(); 9];
            trajectories(9, frames, given.map(|g| &g.torso[..]), &mut m, &|j| j)
        } else {
            Vec::new()
        };
        let mut m = vec![spline::Models::default(); COEF_CONTEXTS];
        let coefs = trajectories(
            model.k(),
            frames,
            given.map(|g| &g.coefs[..]),
            &mut m,
            &coef_context,
        );
        let lead_n = self.lead_frames(segment, frames);
        let lead = if lead_n > 0 {
            let next = &self.params.models[segment + 1];
            let mut m = vec![spline::Models::default(); COEF_CONTEXTS];
            trajectories(
                next.k(),
                lead_n,
                given.map(|g| &g.lead[..]),
                &mut m,
                &coef_context,
            )
        } else {
            Vec::new()
        };
        Ok(ChunkKeys {
            segment,
            torso,
            coefs,
            lead,
        })
    }

    /// Each frame's placement from the torso keys (identity without normalisation), and the
    /// torso points' decoded coordinates (`frames × 9`; empty without).
    pub fn placements(&self, keys: &ChunkKeys, frames: usize) -> (Vec<Placement>, Vec<f64>) {
        let Some((up, _)) = self.params.torso else {
            return (vec![Placement::IDENTITY; frames], Vec::new());
        };
        let mut torso = vec![0.0; frames * 9];
        let mut column = vec![0.0; frames];
        for (c, k) in keys.torso.iter().enumerate() {
            spline::evaluate(&k.at, &k.values(self.params.torso_step), &mut column);
            for (f, v) in column.iter().enumerate() {
                torso[f * 9 + c] = *v;
            }
        }
        let placed = torso.chunks_exact(9).map(|t| placement(t, up)).collect();
        (placed, torso)
    }

    /// The coefficient trajectories of `keys` as `frames × k` rows.
    fn coefficients(&self, keys: &[Keys], frames: usize) -> Vec<f64> {
        let k = keys.len();
        let mut rows = vec![0.0; frames * k];
        let mut column = vec![0.0; frames];
        for (j, key) in keys.iter().enumerate() {
            spline::evaluate(&key.at, &key.values(self.params.coef_step), &mut column);
            for (f, v) in column.iter().enumerate() {
                rows[f * k + j] = *v;
            }
        }
        rows
    }

    /// The normalised poses a chunk decodes to before de-normalisation (`frames × width`):
    /// the segment model's, blended into the next model's over the lead frames.
    pub fn poses(&self, keys: &ChunkKeys, frames: usize) -> Vec<f64> {
        let model = &self.params.models[keys.segment];
        let w = model.width();
        let (k, c) = (model.k(), self.coefficients(&keys.coefs, frames));
        let mut out = vec![0.0; frames * w];
        for (f, x) in out.chunks_exact_mut(w).enumerate() {
            model.pose(&c[f * k..(f + 1) * k], x);
        }
        // A next model of no components still blends: into its mean.
        let lead_n = self.lead_frames(keys.segment, frames);
        if lead_n > 0 {
            let next = &self.params.models[keys.segment + 1];
            let (kn, cn) = (next.k(), self.coefficients(&keys.lead, lead_n));
            let mut y = vec![0.0; w];
            for j in 0..lead_n {
                next.pose(&cn[j * kn..(j + 1) * kn], &mut y);
                let wt = blend_weight(j, lead_n);
                let x = &mut out[(frames - lead_n + j) * w..(frames - lead_n + j + 1) * w];
                for (a, b) in x.iter_mut().zip(&y) {
                    *a += wt * (b - *a);
                }
            }
        }
        out
    }

    /// The frames a chunk decodes to, before any residual layer: `frames × points × 3`.
    pub fn reconstruct(&self, keys: &ChunkKeys, frames: usize, out: &mut [f32]) {
        let (placed, torso) = self.placements(keys, frames);
        let poses = self.poses(keys, frames);
        let w = 3 * self.posed.len();
        let up = self.params.torso.map_or(0, |(up, _)| up);
        for f in 0..frames {
            let o = &mut out[f * self.points * 3..(f + 1) * self.points * 3];
            for (i, &p) in self.posed.iter().enumerate() {
                let q = &poses[f * w + i * 3..f * w + i * 3 + 3];
                let x = to_world(&placed[f], up, [q[0], q[1], q[2]]);
                for a in 0..3 {
                    o[p * 3 + a] = x[a] as f32;
                }
            }
            if let Some((_, t)) = self.params.torso {
                for (j, &p) in t.iter().enumerate() {
                    for a in 0..3 {
                        o[p * 3 + a] = torso[f * 9 + j * 3 + a] as f32;
                    }
                }
            }
        }
    }
}

/// The next model's weight at lead frame `j` of `n`: smoothstep from near 0 to near 1, so
/// that neither the value nor its rate of change jumps where the blend starts or ends.
pub fn blend_weight(j: usize, n: usize) -> f64 {
    let u = (j + 1) as f64 / (n + 1) as f64;
    u * u * (3.0 - 2.0 * u)
}
