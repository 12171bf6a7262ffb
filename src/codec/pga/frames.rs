//! Between a chunk's channel values and its [`Trajectories`]: the encoder's analysis (the
//! root's pose, the end points in the root's frame, the geodesic coordinates of each pose)
//! and the decoder's reconstruction (per frame, IK from the decoded coordinates to the
//! decoded end points, then the channels).

use nalgebra::{UnitQuaternion, Vector3};

use super::chunk::Trajectories;
use super::ik::Solver;
use super::layout::Layout;
use super::model::Geodesics;

/// The trajectories of `frames` frames of channel `values`, coordinates along `g`'s
/// directions.
pub fn analyse(layout: &Layout, g: &Geodesics, values: &[f64], frames: usize) -> Trajectories {
    let cc = layout.channels();
    let chain = layout.chain();
    let mut solver = Solver::new(chain, g.dims());
    let mut inner = vec![UnitQuaternion::identity(); layout.inner_count()];
    let mut t = Trajectories {
        ends: vec![Vec::with_capacity(frames); chain.ends().len()],
        ..Default::default()
    };
    for f in 0..frames {
        let (p, r) = layout.split(&values[f * cc..(f + 1) * cc], &mut inner);
        t.root_position.push(p);
        t.root_orientation.push(r);
        solver.pose_with(chain, |j| inner[j]);
        for (series, &e) in t.ends.iter_mut().zip(chain.ends()) {
            series.push(solver.position(e));
        }
        t.coordinates.push(g.coordinates(&inner));
    }
    t
}

/// How the decoder turns coordinates and end points back into poses.
#[derive(Debug, Clone, PartialEq)]
pub struct Solve {
    /// Per coordinate, the weight of its decoded value against reaching the end points (per
    /// squared unit of the take).
    pub lambda: Vec<f64>,
    /// Levenberg–Marquardt steps per frame; with none, each pose is its decoded coordinates'
    /// and the end points are not used.
    pub iterations: usize,
}

/// The channel values (`frames × channels`, appended to `out`) of decoded trajectories.
pub fn channels(
    layout: &Layout,
    g: &Geodesics,
    t: &Trajectories,
    solve: &Solve,
    out: &mut Vec<f64>,
) {
    let cc = layout.channels();
    let chain = layout.chain();
    let frames = t.root_position.len();
    let mut solver = Solver::new(chain, g.dims());
    let mut inner = vec![UnitQuaternion::identity(); layout.inner_count()];
    let mut targets = vec![Vector3::zeros(); chain.ends().len()];
    let base = out.len();
    out.resize(base + frames * cc, 0.0);
    for f in 0..frames {
        for (target, series) in targets.iter_mut().zip(&t.ends) {
            *target = series[f];
        }
        let reference = &t.coordinates[f];
        if solve.iterations == 0 || targets.len() != t.ends.len() {
            g.pose(reference, &mut inner);
        } else {
            let x = solver.solve(
                chain,
                g,
                &targets,
                reference,
                reference,
                &solve.lambda,
                solve.iterations,
            );
            g.pose(&x, &mut inner);
        }
        let (done, rest) = out[base..].split_at_mut(f * cc);
        let previous = (f > 0).then(|| &done[(f - 1) * cc..]);
        layout.join(
            (t.root_position[f], t.root_orientation[f]),
            &inner,
            previous,
            &mut rest[..cc],
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::entropy::rangecoder::{Decoder, Encoder};
    use crate::codec::pga::chunk::{self, Steps};
    use crate::codec::Skeleton;
    use crate::motion::synthetic::dancer;

    /// The acceptance check of the issue: with every direction and trajectories coded
    /// (nearly) without loss, decoding gives the take back to well under 0.1 mm.
    #[test]
    fn all_directions_and_fine_steps_give_the_take_back() {
        let frames = 90;
        let m = dancer(frames, 60.0, 8);
        let sk = m.skeleton.as_ref().unwrap();
        let rig = Skeleton::new(sk.joints.clone()).unwrap();
        let layout = Layout::new(&rig, &sk.values, frames).unwrap();
        let n = layout.inner_count();
        let cc = rig.channel_count();
        let mut poses = Vec::new();
        let mut inner = vec![UnitQuaternion::identity(); n];
        for f in 0..frames {
            layout.split(&sk.values[f * cc..(f + 1) * cc], &mut inner);
            poses.extend_from_slice(&inner);
        }
        let g = Geodesics::fit(&poses, n, 3 * n).unwrap();
        let t = analyse(&layout, &g, &sk.values, frames);
        let steps = Steps {
            position: 1e-5,
            orientation: 1e-7,
            coordinate: vec![1e-7; 3 * n],
            dead_zone: 0.0,
        };
        let ends = layout.chain().ends().len();
        let mut enc = Encoder::new();
        chunk::code(&mut enc, frames, ends, 3 * n, 16, &steps, Some(&t)).unwrap();
        let bytes = enc.finish();
        let decoded = chunk::code(
            &mut Decoder::new(&bytes),
            frames,
            ends,
            3 * n,
            16,
            &steps,
            None,
        )
        .unwrap();
        let mut values = Vec::new();
        let solve = Solve {
            lambda: vec![1.0; 3 * n],
            iterations: 4,
        };
        channels(&layout, &g, &decoded, &solve, &mut values);
        let mut positions = vec![0f32; m.positions().len()];
        rig.positions(&values, &mut positions);
        let to_mm = m.unit.to_mm();
        let worst = positions
            .iter()
            .zip(m.positions())
            .map(|(a, b)| f64::from((a - b).abs()) * to_mm)
            .fold(0.0, f64::max);
        assert!(worst < 0.1, "{worst} mm");
    }
}
