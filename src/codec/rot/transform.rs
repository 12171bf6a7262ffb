//! `rot`'s transform mode: per chunk, each rotation as its rotation vector (the log map,
//! kept continuous from frame to frame) and each scalar channel as a series along time,
//! each series turned into DCT coefficients, quantised with the part's step, and coded up to
//! its last non-zero coefficient. Best at loose bounds, where a second of a joint's motion
//! takes a handful of coefficients (the MDTT observation, on rotations).

use nalgebra::{UnitQuaternion, Vector3};

use super::aim::{self, Aim, Pose};
use super::{printed, quantise, Given, Part, Plan};
use crate::codec::dct;
use crate::codec::entropy::ints::IntModel;
use crate::codec::entropy::io::{code_residual, Io};
use crate::codec::error::{malformed, Result};
use crate::codec::twists::Twists;
use crate::motion::rotation;

/// Frequency bands with their own statistics: 0, 1, 2, 3–4, 5–8, 9–16, 17+.
const BANDS: usize = 7;
/// Contexts from the previous coefficient's size: 0, 1, 2, 3+.
const PREVIOUS: usize = 4;

fn band(k: usize) -> usize {
    match k {
        0..=2 => k,
        3..=4 => 3,
        5..=8 => 4,
        9..=16 => 5,
        _ => 6,
    }
}

/// The DCT coefficients of one chunk: a series per rotation-vector component and per
/// scalar channel, in the plan's part order. They do not depend on the step, so rate
/// control computes them once.
pub(super) struct Coeffs {
    series: Vec<Vec<f64>>,
    /// The file's rotation of each quaternion part in each frame (empty for scalar parts),
    /// in the plan's part order: every trial aims from these.
    pub(super) rotations: Vec<Vec<UnitQuaternion<f64>>>,
}

/// The series of a chunk's `frames` frames of channel values, as DCT coefficients.
pub(super) fn analyse(plan: &Plan, values: &[f64], frames: usize) -> Coeffs {
    let cc = plan.channels;
    let d = dct::basis(frames, frames);
    let transform = |x: &[f64]| coefficients(x, &d);
    let mut series = Vec::new();
    let mut rotations = Vec::new();
    for part in &plan.parts {
        match *part {
            Part::Scalar { idx, .. } => {
                let x: Vec<f64> = (0..frames).map(|t| values[t * cc + idx]).collect();
                series.push(transform(&x));
                rotations.push(Vec::new());
            }
            Part::Quat { order, idx, .. } => {
                let mut comps = [vec![0.0; frames], vec![0.0; frames], vec![0.0; frames]];
                let mut prev: Option<Vector3<f64>> = None;
                let qs: Vec<_> = (0..frames)
                    .map(|t| {
                        let r = &values[t * cc..];
                        rotation::from_euler(order, [r[idx[0]], r[idx[1]], r[idx[2]]])
                    })
                    .collect();
                for (t, q) in qs.iter().enumerate() {
                    let v = continuous(rotation::log(q), prev);
                    prev = Some(v);
                    for c in 0..3 {
                        comps[c][t] = v[c];
                    }
                }
                series.extend(comps.iter().map(|x| transform(x)));
                rotations.push(qs);
            }
        }
    }
    Coeffs { series, rotations }
}

/// The orthonormal DCT-II coefficients of a series, with `d` its length's [`dct::basis`].
fn coefficients(x: &[f64], d: &[f64]) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|j| (0..n).map(|t| x[t] * d[t * n + j]).sum())
        .collect()
}

/// Of the rotation vectors of one rotation (`v` turned by whole turns along its axis), the
/// one nearest `prev`: a rotation turning past 180° keeps a smooth series.
fn continuous(v: Vector3<f64>, prev: Option<Vector3<f64>>) -> Vector3<f64> {
    let (Some(p), theta) = (prev, v.norm()) else {
        return v;
    };
    if theta < 1e-12 {
        return v;
    }
    let tau = std::f64::consts::TAU;
    [-1.0, 0.0, 1.0]
        .into_iter()
        .map(|k: f64| v * ((theta + k * tau) / theta))
        .min_by(|a, b| (a - p).norm().total_cmp(&(b - p).norm()))
        .unwrap_or(v)
}

/// Code one chunk of `frames` frames (from `coeffs` when encoding), appending the decoded
/// channel values to `out`. Parts are coded one after the other over the whole chunk, so
/// when encoding with `aim` each rotation is aimed from its parents as decoded.
pub(super) fn code_chunk<I: Io>(
    io: &mut I,
    plan: &Plan,
    frames: usize,
    given: Option<&Given>,
    out: &mut Vec<f64>,
) -> Result<()> {
    let cc = plan.channels;
    let d = dct::basis(frames, frames);
    let mut eob_models = vec![IntModel::default(); 3];
    let mut models = vec![IntModel::default(); 3 * BANDS * PREVIOUS];
    let base = out.len();
    out.resize(base + frames * cc, 0.0);
    // When aiming, each frame's pose as far as decoded (parts are decoded joint by joint,
    // so what a pose has computed stays right as the chunk goes on).
    let mut aim = given.and_then(|g| {
        g.aim.as_ref().map(|a| {
            (
                g,
                a,
                (0..frames).map(|_| Pose::new(a.bones)).collect::<Vec<_>>(),
            )
        })
    });
    let mut twists = plan.twists.then(|| Twists::new(plan.parts.len()));
    let mut s = 0;
    for (p, part) in plan.parts.iter().enumerate() {
        let (n, step, kind) = match *part {
            Part::Scalar { step, kind, .. } => (1, step, kind),
            Part::Quat { step, .. } => (3, step, 2),
        };
        // The series to code: as analysed, or aimed from the decoded parents.
        let aimed = match (*part, aim.as_mut()) {
            (Part::Quat { joint, .. }, Some((g, a, poses))) => Some(aimed_series(
                joint,
                &g.coeffs.rotations[p],
                g.values,
                a,
                poses,
                &out[base..],
                cc,
                &d,
            )),
            _ => None,
        };
        let mut decoded: [Vec<f64>; 3] = Default::default();
        for (k, x) in decoded.iter_mut().enumerate().take(n) {
            let given = match &aimed {
                Some(a) => Some(&a[k]),
                None => given.map(|g| &g.coeffs.series[s]),
            };
            s += 1;
            *x = code_series(
                io,
                &mut eob_models,
                &mut models,
                kind,
                step,
                frames,
                given,
                &d,
            )?;
        }
        match *part {
            Part::Scalar { idx, .. } => {
                for t in 0..frames {
                    out[base + t * cc + idx] = printed(decoded[0][t]);
                }
            }
            Part::Quat {
                joint, order, idx, ..
            } => {
                let mut near = None;
                for t in 0..frames {
                    let v = Vector3::new(decoded[0][t], decoded[1][t], decoded[2][t]);
                    let q = rotation::exp(&v);
                    let e = rotation::to_euler(&q, order, near);
                    near = Some(e);
                    // Twisted near lock before the children are aimed from it.
                    let shown = match twists.as_mut() {
                        Some(tw) => {
                            let source = given.map(|g| g.around.source(idx, t));
                            tw.code(io, p, order, e, source)?
                        }
                        None => e,
                    };
                    if let Some((_, _, poses)) = aim.as_mut() {
                        let shown_q = if shown == e {
                            q
                        } else {
                            rotation::from_euler(order, shown)
                        };
                        poses[t].decoded(joint, shown_q);
                    }
                    for k in 0..3 {
                        out[base + t * cc + idx[k]] = printed(shown[k]);
                    }
                }
            }
        }
    }
    Ok(())
}

/// One series' coefficients (from `given` when encoding) through `io`: the decoded series.
#[allow(clippy::too_many_arguments)]
fn code_series<I: Io>(
    io: &mut I,
    eob_models: &mut [IntModel],
    models: &mut [IntModel],
    kind: usize,
    step: f64,
    frames: usize,
    given: Option<&Vec<f64>>,
    d: &[f64],
) -> Result<Vec<f64>> {
    let q: Vec<i64> =
        given.map_or_else(Vec::new, |c| c.iter().map(|v| quantise(v / step)).collect());
    let last = q.iter().rposition(|&v| v != 0).map_or(0, |i| i + 1);
    let eob = io.int(&mut eob_models[kind], last as i32);
    let eob = usize::try_from(eob)
        .ok()
        .filter(|&e| e <= frames)
        .ok_or_else(|| malformed(format!("{eob} coefficients for {frames} frames")))?;
    let mut x = vec![0.0; frames];
    let mut previous = 0i64;
    for k in 0..eob {
        let ctx = (kind * BANDS + band(k)) * PREVIOUS
            + (previous.unsigned_abs().min(PREVIOUS as u64 - 1) as usize);
        let v = code_residual(io, &mut models[ctx], q.get(k).copied().unwrap_or(0))?;
        previous = v;
        if v != 0 {
            let c = v as f64 * step;
            for (t, x) in x.iter_mut().enumerate() {
                *x += c * d[t * frames + k];
            }
        }
    }
    if !x.iter().all(|v| v.is_finite()) {
        return Err(malformed("a decoded series is not finite"));
    }
    Ok(x)
}

/// The DCT coefficients of joint `joint`'s rotation vectors over the chunk, each frame's
/// rotation (`rotations`, the file's) aimed ([`super::aim`]) from the parents decoded so far
/// (`decoded`, the chunk's rows; `poses`, each frame's pose as far as decoded).
#[allow(clippy::too_many_arguments)]
fn aimed_series(
    joint: usize,
    rotations: &[UnitQuaternion<f64>],
    values: &[f64],
    a: &Aim,
    poses: &mut [Pose],
    decoded: &[f64],
    cc: usize,
    d: &[f64],
) -> [Vec<f64>; 3] {
    let frames = rotations.len();
    let mut comps = [vec![0.0; frames], vec![0.0; frames], vec![0.0; frames]];
    let mut prev: Option<Vector3<f64>> = None;
    for (t, pose) in poses.iter_mut().enumerate() {
        let q = aim::aim(
            a.bones,
            pose,
            joint,
            rotations[t],
            &decoded[t * cc..(t + 1) * cc],
            &values[t * cc..(t + 1) * cc],
            a.frame(t),
        );
        let v = continuous(rotation::log(&q), prev);
        prev = Some(v);
        for c in 0..3 {
            comps[c][t] = v[c];
        }
    }
    comps.map(|x| coefficients(&x, d))
}
