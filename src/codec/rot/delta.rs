//! `rot`'s delta mode: each frame predicted from the two decoded before it (constant
//! angular velocity for rotations, linear extrapolation for scalars) and the residual
//! quantised — closed loop, so errors never accumulate. Best at tight bounds, where the
//! residuals are small against the step.

use nalgebra::{UnitQuaternion, Vector3};

use super::aim::{self, Pose};
use super::{printed, quantise, Given, Part, Plan, Version, SIZE_CONTEXTS};
use crate::codec::entropy::ints::IntModel;
use crate::codec::entropy::io::{code_residual, Io};
use crate::codec::entropy::rangecoder::Bit;
use crate::codec::error::{malformed, Result};
use crate::codec::twists::Twists;
use crate::motion::rotation;

/// What one part has decoded so far in the chunk.
#[derive(Clone, Default)]
struct History {
    quats: [Option<UnitQuaternion<f64>>; 2],
    euler: Option<[f64; 3]>,
    scalars: [Option<f64>; 2],
    /// Running mean of residual magnitudes, × 16, per component.
    size: [u32; 3],
    /// The part's predictor: constant velocity, or the last value.
    extrapolate: bool,
}

fn size_context(size: u32) -> usize {
    ((32 - (size >> 4).leading_zeros()) as usize).min(SIZE_CONTEXTS - 1)
}

fn seen(size: &mut u32, r: i64) {
    let r = r.unsigned_abs().min(1 << 24) as u32;
    *size = (3 * *size + 16 * r) / 4;
}

/// Code `frames` frames of one chunk (closed loop), appending the decoded channel values to
/// `out`: from `input` (this chunk's channel values) when encoding.
pub(super) fn code_chunk<I: Io>(
    io: &mut I,
    plan: &Plan,
    frames: usize,
    given: Option<&Given>,
    out: &mut Vec<f64>,
) -> Result<()> {
    let cc = plan.channels;
    let aim = given.and_then(|g| g.aim.as_ref());
    let mut pose = aim.map(|a| Pose::new(a.bones));
    let mut models = vec![IntModel::default(); 3 * SIZE_CONTEXTS];
    let mut hist = vec![History::default(); plan.parts.len()];
    // Each part's predictor: extrapolate (constant velocity) or hold the last value, which
    // wins where the motion is slow against the capture's noise (extrapolation doubles the
    // noise it predicts from).
    let mut extrapolate_model = Bit::default();
    for (p, (part, h)) in plan.parts.iter().zip(&mut hist).enumerate() {
        h.extrapolate = match plan.version {
            Version::V1 => true,
            Version::V2 | Version::V3 | Version::V4 => {
                let want = given.is_some_and(|g| {
                    extrapolates(part, &g.coeffs.rotations[p], g.values, cc, frames)
                });
                io.bit(&mut extrapolate_model, want)
            }
        };
    }
    let mut twists = plan.twists.then(|| Twists::new(plan.parts.len()));
    let base = out.len();
    out.resize(base + frames * cc, 0.0);
    for f in 0..frames {
        let row = given.map(|g| &g.values[f * cc..(f + 1) * cc]);
        let mut aim = aim.zip(pose.as_mut()).map(|(a, p)| {
            p.clear();
            (a, p)
        });
        let dest = &mut out[base + f * cc..base + (f + 1) * cc];
        for (p, (part, h)) in plan.parts.iter().zip(&mut hist).enumerate() {
            match *part {
                Part::Scalar { idx, step, kind } => {
                    let pred = match h.scalars {
                        [Some(a), Some(b)] if h.extrapolate => 2.0 * a - b,
                        [Some(a), _] => a,
                        _ => 0.0,
                    };
                    let q = row.map_or(0, |r| quantise((r[idx] - pred) / step));
                    let m = &mut models[kind * SIZE_CONTEXTS + size_context(h.size[0])];
                    let q = code_residual(io, m, q)?;
                    seen(&mut h.size[0], q);
                    let v = printed(pred + q as f64 * step);
                    if !v.is_finite() {
                        return Err(malformed("a decoded channel value is not finite"));
                    }
                    h.scalars = [Some(v), h.scalars[0]];
                    dest[idx] = v;
                }
                Part::Quat {
                    joint,
                    order,
                    idx,
                    step,
                } => {
                    let pred = match h.quats {
                        [Some(a), Some(b)] if h.extrapolate => a * (b.inverse() * a),
                        [Some(a), _] => a,
                        _ => UnitQuaternion::identity(),
                    };
                    let residual = given.zip(row).map(|(g, r)| {
                        let mut q = g.coeffs.rotations[p][f];
                        if let Some((a, pose)) = aim.as_mut() {
                            q = aim::aim(a.bones, pose, joint, q, dest, r, a.frame(f));
                        }
                        rotation::log(&(pred.inverse() * q))
                    });
                    let mut v = Vector3::zeros();
                    for c in 0..3 {
                        let q = residual.map_or(0, |r| quantise(r[c] / step));
                        let m = &mut models[2 * SIZE_CONTEXTS + size_context(h.size[c])];
                        let q = code_residual(io, m, q)?;
                        seen(&mut h.size[c], q);
                        v[c] = q as f64 * step;
                    }
                    if !v.iter().all(|x| x.is_finite()) {
                        return Err(malformed("a decoded rotation is not finite"));
                    }
                    // Renormalised: extrapolation multiplies small departures from unit norm
                    // frame after frame.
                    let q = UnitQuaternion::new_normalize((pred * rotation::exp(&v)).into_inner());
                    let e = rotation::to_euler(&q, order, h.euler);
                    h.euler = Some(e);
                    h.quats = [Some(q), h.quats[0]];
                    // Twisted near lock before the children are aimed from it.
                    let shown = match twists.as_mut() {
                        Some(tw) => {
                            tw.code(io, p, order, e, given.map(|g| g.around.source(idx, f)))?
                        }
                        None => e,
                    };
                    if let Some((_, pose)) = aim.as_mut() {
                        let shown_q = if shown == e {
                            q
                        } else {
                            rotation::from_euler(order, shown)
                        };
                        pose.decoded(joint, shown_q);
                    }
                    for k in 0..3 {
                        dest[idx[k]] = printed(shown[k]);
                    }
                }
            }
        }
    }
    Ok(())
}

/// Whether `part` of a chunk (`values`, `frames` rows of `cc`) costs fewer bits predicted at
/// constant velocity than by its last value, by an open-loop estimate on the values as given
/// (the bit lengths of the residuals in steps).
fn extrapolates(
    part: &Part,
    rotations: &[UnitQuaternion<f64>],
    values: &[f64],
    cc: usize,
    frames: usize,
) -> bool {
    let bits = |x: f64| (1.0 + x.abs()).log2();
    let (mut hold, mut extrapolate) = (0.0, 0.0);
    match *part {
        Part::Scalar { idx, step, .. } => {
            let v = |t: usize| values[t * cc + idx] / step;
            for t in 2..frames {
                hold += bits(v(t) - v(t - 1));
                extrapolate += bits(v(t) - 2.0 * v(t - 1) + v(t - 2));
            }
        }
        Part::Quat { step, .. } => {
            let q = |t: usize| rotations[t];
            let cost = |pred: UnitQuaternion<f64>, q: UnitQuaternion<f64>| {
                rotation::log(&(pred.inverse() * q))
                    .iter()
                    .map(|c| bits(c / step))
                    .sum::<f64>()
            };
            for t in 2..frames {
                let (a, b, c) = (q(t - 1), q(t - 2), q(t));
                hold += cost(a, c);
                extrapolate += cost(a * (b.inverse() * a), c);
            }
        }
    }
    extrapolate < hold
}
