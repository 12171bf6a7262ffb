//! Resampling a skeleton's channel values: each joint's rotation by slerp in the joint's own
//! frame (its three Euler channels to a unit quaternion and back, in the joint's order and
//! continuous with the frame before), positions by [`cubic`].

use nalgebra::UnitQuaternion;

use super::resample::{cubic, Interpolant};
use crate::motion::rotation::{euler_order, from_euler, to_euler};
use crate::motion::skeleton::Joint;

/// How one joint's channels are formed between two frames.
#[derive(Debug, Clone)]
enum Part {
    /// Three rotation channels about different axes, at these offsets in the joint's
    /// channels, in this order: slerp.
    Euler { at: [usize; 3], order: [usize; 3] },
    /// A channel by itself: [`cubic`] (positions, and rotation channels that are not three
    /// Euler angles, which are coded one by one as well).
    Scalar(usize),
}

/// The interpolant of a skeleton's channel values (`frames × channels`, file order).
#[derive(Debug, Clone)]
pub struct Channels {
    width: usize,
    parts: Vec<Part>,
}

impl Channels {
    pub fn new(joints: &[Joint]) -> Channels {
        let mut parts = Vec::new();
        let mut k = 0;
        for j in joints {
            let rot: Vec<usize> = (0..j.channels.len())
                .filter(|&c| j.channels[c].rotation_axis().is_some())
                .collect();
            let euler = euler_order(&j.channels).filter(|_| rot.len() == 3);
            for c in 0..j.channels.len() {
                if euler.is_none() || !rot.contains(&c) {
                    parts.push(Part::Scalar(k + c));
                }
            }
            if let Some(order) = euler {
                parts.push(Part::Euler {
                    at: [k + rot[0], k + rot[1], k + rot[2]],
                    order,
                });
            }
            k += j.channels.len();
        }
        Channels { width: k, parts }
    }
}

/// `q` slerped towards `r` by `f`, on the shorter arc.
pub fn slerp(q: &UnitQuaternion<f64>, r: &UnitQuaternion<f64>, f: f64) -> UnitQuaternion<f64> {
    let r = if q.coords.dot(&r.coords) < 0.0 {
        UnitQuaternion::new_unchecked(-r.into_inner())
    } else {
        *r
    };
    q.slerp(&r, f)
}

impl Interpolant for Channels {
    fn width(&self) -> usize {
        self.width
    }

    fn between(
        &self,
        before: Option<&[f64]>,
        a: &[f64],
        b: &[f64],
        after: Option<&[f64]>,
        f: f64,
        out: &mut [f64],
    ) {
        for part in &self.parts {
            match *part {
                Part::Scalar(c) => {
                    out[c] = cubic(before.map(|v| v[c]), a[c], b[c], after.map(|v| v[c]), f);
                }
                Part::Euler { at, order } => {
                    let angles = |v: &[f64]| [v[at[0]], v[at[1]], v[at[2]]];
                    let (ea, eb) = (angles(a), angles(b));
                    let q = slerp(&from_euler(order, ea), &from_euler(order, eb), f);
                    // Continuous with `a`: the same turn of each angle, not a jump of 360°.
                    let e = to_euler(&q, order, Some(ea));
                    for (&c, v) in at.iter().zip(e) {
                        out[c] = v;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::resample::Resampler;
    use super::*;
    use crate::motion::skeleton::Channel;

    fn joints() -> Vec<Joint> {
        use Channel::*;
        vec![
            Joint {
                name: "hips".into(),
                parent: None,
                offset: [0.0; 3],
                channels: vec![
                    Xposition, Yposition, Zposition, Zrotation, Xrotation, Yrotation,
                ],
                end_site: false,
            },
            Joint {
                name: "knee".into(),
                parent: Some(0),
                offset: [0.0, -40.0, 0.0],
                channels: vec![Xrotation],
                end_site: false,
            },
        ]
    }

    /// Halfway between two rotations about one axis is the rotation by half the angle; the
    /// result is a unit quaternion; angles stay continuous across ±180°.
    #[test]
    fn slerp_halves_turns_and_stays_on_the_sphere() {
        let c = Channels::new(&joints());
        assert_eq!(c.width(), 7);
        let a = [0.0, 90.0, 0.0, 170.0, 0.0, 0.0, 10.0];
        let b = [2.0, 90.0, 0.0, 190.0, 0.0, 0.0, 30.0];
        let mut out = [0.0; 7];
        c.between(None, &a, &b, None, 0.5, &mut out);
        assert!((out[0] - 1.0).abs() < 1e-12);
        assert!((out[3] - 180.0).abs() < 1e-9, "{out:?}");
        assert!(out[4].abs() < 1e-9 && out[5].abs() < 1e-9, "{out:?}");
        assert!((out[6] - 20.0).abs() < 1e-12);
        for f in [0.0, 0.25, 0.7, 1.0] {
            let q = slerp(
                &from_euler([2, 0, 1], [10.0, 20.0, 30.0]),
                &from_euler([2, 0, 1], [-170.0, 40.0, 80.0]),
                f,
            );
            assert!((q.coords.norm() - 1.0).abs() < 1e-12);
        }
    }

    /// 30 → 120 → 30 fps gives the channels back (every fourth frame is a source frame).
    #[test]
    fn up_and_back_gives_the_source() {
        let c = Channels::new(&joints());
        let src: Vec<f64> = (0..31)
            .flat_map(|i| {
                let t = i as f64 / 30.0;
                [t, 90.0, 0.0, 100.0 * t, 30.0 * t.sin(), 5.0, 45.0 * t.cos()]
            })
            .collect();
        let mut up = Resampler::new(c.clone(), 31, 30.0, 120.0);
        let mut fine = Vec::new();
        up.push(&src, &mut fine);
        assert_eq!(fine.len(), 121 * 7);
        let mut down = Resampler::new(c, 121, 120.0, 30.0);
        let mut back = Vec::new();
        down.push(&fine, &mut back);
        assert_eq!(back, src);
    }
}
