//! One chunk of a `pga` take as trajectories: the root's position and orientation, each end
//! point's position in the root's frame, and the geodesic coordinates — each through the
//! closed-loop [`lifting`](super::lifting) with its own step, the quantised details to the
//! adaptive range coder (contexts by trajectory kind and lifting level). Every chunk carries
//! its own pyramids, so it decodes without its neighbours.

use nalgebra::{UnitQuaternion, Vector3};

use super::lifting::{self, Orientations, Positions};
use crate::codec::entropy::ints::IntModel;
use crate::codec::entropy::io::{code_residual, Io};
use crate::codec::error::{malformed, Error, Result};

/// Lifting levels with their own statistics: the coarse samples, then levels by stride.
const LEVELS: usize = 8;
const KINDS: usize = 4;

/// The steps details are quantised with.
#[derive(Debug, Clone, PartialEq)]
pub struct Steps {
    /// Root and end positions (the take's units).
    pub position: f64,
    /// Root orientation (radians).
    pub orientation: f64,
    /// Each geodesic coordinate's.
    pub coordinate: Vec<f64>,
    /// The encoder drops details within `½ + dead_zone` steps of zero (0: plain rounding):
    /// zeros are what the range coder codes cheapest, and the lifting is closed loop, so a
    /// dropped detail costs its own sample's error only. Nothing the decoder needs.
    pub dead_zone: f64,
}

/// A chunk's trajectories, frame by frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trajectories {
    pub root_position: Vec<Vector3<f64>>,
    pub root_orientation: Vec<UnitQuaternion<f64>>,
    /// Per end point, its positions in the root's frame.
    pub ends: Vec<Vec<Vector3<f64>>>,
    /// Per frame, the `k` coordinates.
    pub coordinates: Vec<Vec<f64>>,
}

/// Code a chunk of `frames` frames with `ends` end points and `k` coordinates, from `given`
/// when encoding; returns the trajectories as decoded.
#[allow(clippy::too_many_arguments)]
pub fn code<I: Io>(
    io: &mut I,
    frames: usize,
    ends: usize,
    k: usize,
    stride: usize,
    steps: &Steps,
    given: Option<&Trajectories>,
) -> Result<Trajectories> {
    if steps.coordinate.len() != k {
        return Err(Error::Invalid(format!(
            "{} coordinate steps for {k} coordinates",
            steps.coordinate.len()
        )));
    }
    let mut models = vec![IntModel::default(); KINDS * LEVELS];
    let mut failed: Option<Error> = None;
    let mut series = |io: &mut I,
                      kind: usize,
                      step: [f64; 3],
                      detail: Vector3<f64>,
                      t: usize,
                      failed: &mut Option<Error>|
     -> Vector3<f64> {
        let level = if t.is_multiple_of(stride) {
            LEVELS - 1
        } else {
            (t.trailing_zeros() as usize).min(LEVELS - 2)
        };
        let m = &mut models[kind * LEVELS + level];
        let mut out = Vector3::zeros();
        for c in 0..3 {
            let r = detail[c] / step[c];
            let q = if r.abs() < 0.5 + steps.dead_zone {
                0
            } else {
                r.round().clamp(-(2f64.powi(62)), 2f64.powi(62)) as i64
            };
            match code_residual(io, m, q) {
                Ok(v) => out[c] = v as f64 * step[c],
                Err(e) => {
                    failed.get_or_insert(e);
                }
            }
        }
        out
    };
    let root_position = lifting::code::<Positions>(
        frames,
        stride,
        given.map(|g| &g.root_position[..]),
        |t, d| series(io, 0, [steps.position; 3], d, t, &mut failed),
    );
    let root_orientation = lifting::code::<Orientations>(
        frames,
        stride,
        given.map(|g| &g.root_orientation[..]),
        |t, d| series(io, 1, [steps.orientation; 3], d, t, &mut failed),
    );
    let mut end_series = Vec::with_capacity(ends);
    for e in 0..ends {
        end_series.push(lifting::code::<Positions>(
            frames,
            stride,
            given.map(|g| &g.ends[e][..]),
            |t, d| series(io, 2, [steps.position; 3], d, t, &mut failed),
        ));
    }
    // Coordinates three at a time (the last group padded with zeros) as points.
    let mut coordinates = vec![vec![0.0; k]; frames];
    for group in 0..k.div_ceil(3) {
        let step: [f64; 3] =
            std::array::from_fn(|c| steps.coordinate.get(3 * group + c).copied().unwrap_or(1.0));
        let samples: Option<Vec<Vector3<f64>>> = given.map(|g| {
            g.coordinates
                .iter()
                .map(|x| Vector3::from_fn(|c, _| x.get(3 * group + c).copied().unwrap_or(0.0)))
                .collect()
        });
        let decoded = lifting::code::<Positions>(frames, stride, samples.as_deref(), |t, d| {
            series(io, 3, step, d, t, &mut failed)
        });
        for (x, v) in coordinates.iter_mut().zip(&decoded) {
            for c in 0..3 {
                if let Some(slot) = x.get_mut(3 * group + c) {
                    *slot = v[c];
                }
            }
        }
    }
    if let Some(e) = failed {
        return Err(e);
    }
    let finite = root_position
        .iter()
        .all(|p| p.iter().all(|v| v.is_finite()))
        && root_orientation
            .iter()
            .all(|q| q.coords.iter().all(|v| v.is_finite()))
        && end_series
            .iter()
            .flatten()
            .all(|p| p.iter().all(|v| v.is_finite()))
        && coordinates.iter().flatten().all(|v| v.is_finite());
    if !finite {
        return Err(malformed(
            "a pga trajectory decodes to a value that is not finite",
        ));
    }
    Ok(Trajectories {
        root_position,
        root_orientation: root_orientation
            .into_iter()
            .map(|q| UnitQuaternion::new_normalize(q.into_inner()))
            .collect(),
        ends: end_series,
        coordinates,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::entropy::rangecoder::{Decoder, Encoder};

    fn trajectories(frames: usize, ends: usize, k: usize) -> Trajectories {
        let f = |t: usize, a: f64| (t as f64 * 0.05 + a).sin();
        Trajectories {
            root_position: (0..frames)
                .map(|t| Vector3::new(10.0 * f(t, 0.0), 90.0 + f(t, 1.0), t as f64 * 0.3))
                .collect(),
            root_orientation: (0..frames)
                .map(|t| UnitQuaternion::from_euler_angles(0.1 * f(t, 2.0), 0.02 * t as f64, 0.0))
                .collect(),
            ends: (0..ends)
                .map(|e| {
                    (0..frames)
                        .map(|t| Vector3::new(20.0 * f(t, e as f64), 50.0, -f(t, 0.5)))
                        .collect()
                })
                .collect(),
            coordinates: (0..frames)
                .map(|t| (0..k).map(|i| f(t, i as f64) / (1.0 + i as f64)).collect())
                .collect(),
        }
    }

    #[test]
    fn a_chunk_decodes_to_what_the_encoder_reconstructed_within_half_a_step() {
        let (frames, ends, k) = (45, 5, 7);
        let t = trajectories(frames, ends, k);
        let steps = Steps {
            position: 0.1,
            orientation: 1e-3,
            coordinate: vec![1e-2; k],
            dead_zone: 0.0,
        };
        let mut enc = Encoder::new();
        let coded = code(&mut enc, frames, ends, k, 16, &steps, Some(&t)).unwrap();
        let bytes = enc.finish();
        let mut dec = Decoder::new(&bytes);
        let decoded = code(&mut dec, frames, ends, k, 16, &steps, None).unwrap();
        assert_eq!(decoded, coded);
        for (a, b) in coded.root_position.iter().zip(&t.root_position) {
            assert!((a - b).amax() <= 0.05 + 1e-9);
        }
        for (a, b) in coded.root_orientation.iter().zip(&t.root_orientation) {
            // Half a step per rotation-vector component.
            assert!(a.angle_to(b) <= 1e-3 * 3f64.sqrt() / 2.0 + 1e-9);
        }
        for (x, y) in coded.coordinates.iter().zip(&t.coordinates) {
            assert_eq!(x.len(), k);
            assert!(x.iter().zip(y).all(|(a, b)| (a - b).abs() <= 5e-3 + 1e-9));
        }
        // Smooth trajectories cost little: far under the 32 bits of a float per value.
        let values = frames * (3 + 3 + 3 * ends + k);
        assert!(bytes.len() * 8 < values * 8, "{} bytes", bytes.len());
    }

    #[test]
    fn damaged_chunks_fail_cleanly() {
        let t = trajectories(30, 3, 4);
        let steps = Steps {
            position: 0.5,
            orientation: 1e-2,
            coordinate: vec![1e-2; 4],
            dead_zone: 0.0,
        };
        let mut enc = Encoder::new();
        code(&mut enc, 30, 3, 4, 8, &steps, Some(&t)).unwrap();
        let bytes = enc.finish();
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x5a;
            let _ = code(&mut Decoder::new(&b), 30, 3, 4, 8, &steps, None);
        }
    }
}
