//! How far things move the skeleton, which sets every step `pga` quantises with from the one
//! length `α` a chunk is coded at: root and end positions step by `α`; the root's
//! orientation by `α` over the skeleton's reach (a turn of the root moves the farthest point
//! by reach × angle); coordinate `i` by `ρ α` over its lever (how far a unit of it moves the
//! joints, weighted by what hangs below each). The IK weights come from the same levers, so
//! `λ` compares coordinate and end-point errors in the take's units.

use super::chunk::Steps;
use super::ik::Chain;
use super::model::Geodesics;

/// The lengths of one rig and model.
#[derive(Debug, Clone)]
pub struct Scale {
    /// The longest path of bones from the root to a point below it.
    pub reach: f64,
    /// Per coordinate: `√Σ_j |V_j,i|² reach_j²`.
    pub lever: Vec<f64>,
}

/// Each link's reach: the longest path of bones from it to a point below it. Path lengths,
/// not distances: an upper bound that holds in every pose.
fn reaches(chain: &Chain) -> Vec<f64> {
    let links = chain.links();
    let mut reach = vec![0f64; links.len()];
    for (i, l) in links.iter().enumerate().rev() {
        if let Some(p) = l.parent {
            reach[p] = reach[p].max(reach[i] + l.translation.norm());
        }
    }
    reach
}

/// The root's reach ([`Scale::reach`]) before there is a model.
pub fn reach(chain: &Chain) -> f64 {
    reaches(chain).first().copied().unwrap_or(0.0)
}

/// The least lever a coordinate has, as a fraction of the reach, for parameters `version`.
/// Version 4 raised it from 10⁻³ to 1.5 %: a coordinate no position shows (a hand whose End
/// Site sits at the wrist) was stepped so coarsely that its Euler channels came back up to
/// 90° off and jumped where the file's do not; at 1.5 % they stay within 14° (corpus BVH,
/// 1 mm) for 1.7 % more bits.
pub fn lever_floor(version: u8) -> f64 {
    if version >= 4 {
        0.015
    } else {
        1e-3
    }
}

impl Scale {
    /// The lengths of `chain` and model `g`, every lever at least `floor` × the reach
    /// ([`lever_floor`]).
    pub fn new(chain: &Chain, g: &Geodesics, floor: f64) -> Scale {
        let links = chain.links();
        let reach = reaches(chain);
        let top = reach.first().copied().unwrap_or(0.0);
        let floor = if top > 0.0 { floor * top } else { 1.0 };
        let mut joint_reach = vec![0f64; g.joints()];
        for (i, l) in links.iter().enumerate() {
            if let Some(j) = l.inner.filter(|&j| j < joint_reach.len()) {
                joint_reach[j] = reach[i];
            }
        }
        let lever = (0..g.dims())
            .map(|c| {
                let column = g.directions.column(c);
                let sum: f64 = joint_reach
                    .iter()
                    .enumerate()
                    .map(|(j, r)| column.rows(3 * j, 3).norm_squared() * r * r)
                    .sum();
                sum.sqrt().max(floor)
            })
            .collect();
        Scale {
            reach: top.max(floor),
            lever,
        }
    }

    /// The steps at length `alpha` with coordinates `rho` times coarser.
    pub fn steps(&self, alpha: f64, rho: f64) -> Steps {
        Steps {
            position: alpha,
            orientation: alpha / self.reach,
            coordinate: self.lever.iter().map(|l| rho * alpha / l).collect(),
            dead_zone: 0.0,
        }
    }

    /// The IK weights of the coordinates for `lambda`.
    pub fn weights(&self, lambda: f64) -> Vec<f64> {
        self.lever.iter().map(|l| lambda * l * l).collect()
    }
}

/// A chunk's `α` for its step index `k` (one byte): `base · 2^((k − 224)/8)`, so that a chunk
/// is coded at the largest step its own motion allows, from 2⁻²⁸ to 2⁴ times the bound.
pub fn alpha(base: f64, k: u32) -> f64 {
    base * 2f64.powf((f64::from(k) - 224.0) / 8.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::pga::ik::Link;
    use nalgebra::{DMatrix, UnitQuaternion, Vector3};

    #[test]
    fn levers_weigh_each_joint_by_what_hangs_below_it() {
        // Root → a (10) → b (5) → end (3): a reaches 8, b reaches 3.
        let l = |parent, t: f64, inner| Link {
            parent: Some(parent),
            translation: Vector3::new(t, 0.0, 0.0),
            inner,
        };
        let links = vec![
            Link {
                parent: None,
                translation: Vector3::zeros(),
                inner: None,
            },
            l(0, 10.0, Some(0)),
            l(1, 5.0, Some(1)),
            l(2, 3.0, None),
        ];
        let chain = Chain::new(links, vec![3]).unwrap();
        let mut directions = DMatrix::zeros(6, 2);
        directions[(2, 0)] = 1.0; // Turns a about z.
        directions[(5, 1)] = 1.0; // Turns b about z.
        let g = Geodesics::new(vec![UnitQuaternion::identity(); 2], directions).unwrap();
        let s = Scale::new(&chain, &g, lever_floor(3));
        assert_eq!(s.reach, 18.0);
        assert_eq!(s.lever, vec![8.0, 3.0]);
        let steps = s.steps(0.5, 2.0);
        assert_eq!(steps.position, 0.5);
        assert_eq!(steps.coordinate, vec![1.0 / 8.0, 1.0 / 3.0]);
        assert_eq!(s.weights(2.0), vec![128.0, 18.0]);
        // Levers below the floor (a fraction of the reach) are raised to it.
        let floored = Scale::new(&chain, &g, 0.25);
        assert_eq!(floored.lever, vec![8.0, 4.5]);
        assert!(lever_floor(4) > lever_floor(3));
        assert_eq!(alpha(3.0, 224), 3.0);
        assert_eq!(alpha(3.0, 232), 6.0);
    }
}
