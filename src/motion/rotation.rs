//! The rotation model of skeleton takes: a joint's Euler channels (any order, degrees, BVH's
//! convention `R = R_c0 · R_c1 · R_c2`) to a unit quaternion and back, and the exp/log maps
//! between rotations and rotation vectors. Codecs that code rotations work on quaternions
//! (no gimbal lock, no wrap-around) and give back Euler channels in each joint's own order.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::skeleton::Channel;

/// The rotation axes of a joint with exactly three rotation channels about three different
/// axes (0 = x, 1 = y, 2 = z), in channel order; `None` for any other joint (its rotation
/// channels are then coded one by one).
pub fn euler_order(channels: &[Channel]) -> Option<[usize; 3]> {
    let axes: Vec<usize> = channels.iter().filter_map(|c| c.rotation_axis()).collect();
    match axes[..] {
        [a, b, c] if a != b && b != c && a != c => Some([a, b, c]),
        _ => None,
    }
}

fn axis(a: usize) -> nalgebra::Unit<Vector3<f64>> {
    match a {
        0 => Vector3::x_axis(),
        1 => Vector3::y_axis(),
        _ => Vector3::z_axis(),
    }
}

/// The rotation of Euler angles (degrees) about `order`'s axes, composed left to right.
pub fn from_euler(order: [usize; 3], degrees: [f64; 3]) -> UnitQuaternion<f64> {
    let q = |k: usize| UnitQuaternion::from_axis_angle(&axis(order[k]), degrees[k].to_radians());
    q(0) * q(1) * q(2)
}

/// Euler angles (degrees) of `q` about `order`'s axes; of the two solutions (and their 360°
/// turns), the one nearest `near` (the previous frame's angles, for continuity), or the one
/// with the middle angle in [-90°, 90°] when there is none.
pub fn to_euler(q: &UnitQuaternion<f64>, order: [usize; 3], near: Option<[f64; 3]>) -> [f64; 3] {
    let m: Matrix3<f64> = q.to_rotation_matrix().into_inner();
    let [i, j, k] = order;
    // +1 for the cyclic orders (xyz, yzx, zxy), -1 for the others.
    let s = if (j + 3 - i) % 3 == 1 { 1.0 } else { -1.0 };
    // cos β from the two entries beside sin β: atan2 keeps β exact near ±90°, where asin
    // of a value near 1 loses half the digits.
    let cb = m[(i, i)].hypot(m[(i, j)]);
    let b = (s * m[(i, k)]).atan2(cb);
    let (a, c) = if cb > 1e-12 {
        (
            (-s * m[(j, k)]).atan2(m[(k, k)]),
            (-s * m[(i, j)]).atan2(m[(i, i)]),
        )
    } else {
        // Gimbal lock: only a combination of the first and last angle is determined; put
        // it all in the last, choosing the sign that rebuilds the matrix.
        let best = [1.0, -1.0]
            .into_iter()
            .map(|sign: f64| {
                let c = (sign * m[(j, i)]).atan2(m[(j, j)]);
                let r = from_euler(order, [0.0, b.to_degrees(), c.to_degrees()]);
                (r.angle_to(q), c)
            })
            .min_by(|x, y| x.0.total_cmp(&y.0))
            .map_or(0.0, |x| x.1);
        (0.0, best)
    };
    let first = [a.to_degrees(), b.to_degrees(), c.to_degrees()];
    let Some(prev) = near else {
        return first;
    };
    let second = [first[0] + 180.0, 180.0 - first[1], first[2] + 180.0];
    let unwrap = |e: [f64; 3]| -> [f64; 3] {
        let mut out = e;
        for (v, p) in out.iter_mut().zip(prev) {
            *v += 360.0 * ((p - *v) / 360.0).round();
        }
        out
    };
    let (x, y) = (unwrap(first), unwrap(second));
    let dist = |e: &[f64; 3]| e.iter().zip(prev).map(|(a, b)| (a - b).abs()).sum::<f64>();
    if dist(&y) < dist(&x) {
        y
    } else {
        x
    }
}

/// The rotation vector (axis × angle, radians, angle in [0, π]) of `q`: the log map.
pub fn log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    q.scaled_axis()
}

/// The rotation of a rotation vector: the exp map.
pub fn exp(v: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_scaled_axis(*v)
}

/// The intrinsic (Karcher) mean of rotations: the rotation `μ` at which the rotation vectors
/// `log(μ⁻¹ q)` of the samples average to zero, found by the usual fixed-point iteration
/// `μ ← μ · exp(mean log(μ⁻¹ q))` from the first sample. Stops when the update turns less than
/// `1e-12` rad or after `iterations`. `None` for no samples.
///
/// The mean of a product of rotation groups (a pose: one rotation per joint) is the mean of
/// each factor, so this is also the Karcher mean of SO(3)ⁿ joint by joint.
pub fn karcher_mean(
    samples: &[UnitQuaternion<f64>],
    iterations: usize,
) -> Option<UnitQuaternion<f64>> {
    let mut mu = *samples.first()?;
    let n = samples.len() as f64;
    for _ in 0..iterations {
        let inv = mu.inverse();
        let step: Vector3<f64> = samples
            .iter()
            .map(|q| log(&(inv * q)))
            .sum::<Vector3<f64>>()
            / n;
        mu *= exp(&step);
        if step.norm() < 1e-12 {
            break;
        }
    }
    Some(mu)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    const ORDERS: [[usize; 3]; 6] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];

    #[test]
    fn euler_angles_round_trip_in_every_order() {
        let mut rng = Rng::new(4);
        for order in ORDERS {
            for n in 0..500 {
                let mut e = [
                    rng.unit() * 360.0 - 180.0,
                    rng.unit() * 180.0 - 90.0,
                    rng.unit() * 360.0 - 180.0,
                ];
                if n % 50 == 0 {
                    e[1] = 90.0; // gimbal lock
                }
                let q = from_euler(order, e);
                let back = to_euler(&q, order, None);
                assert!(
                    from_euler(order, back).angle_to(&q) < 1e-9,
                    "{order:?} {e:?} -> {back:?}"
                );
                if n % 50 != 0 {
                    for (a, b) in back.iter().zip(e) {
                        assert!((a - b).abs() < 1e-7, "{order:?} {e:?} -> {back:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn angles_stay_continuous_past_180_degrees() {
        let order = [2, 0, 1];
        let e = [190.0, 10.0, -200.0];
        let back = to_euler(&from_euler(order, e), order, Some([185.0, 12.0, -195.0]));
        for (a, b) in back.iter().zip(e) {
            assert!((a - b).abs() < 1e-7, "{back:?}");
        }
    }

    #[test]
    fn the_karcher_mean_of_rotations_spread_around_one_is_that_one() {
        let mut rng = Rng::new(11);
        let centre = from_euler([2, 0, 1], [40.0, -25.0, 130.0]);
        // Symmetric pairs about the centre (exact mean), then random spread (mean within
        // the sampling error).
        let mut samples = Vec::new();
        for _ in 0..50 {
            let v = Vector3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 1.2;
            samples.push(centre * exp(&v));
            samples.push(centre * exp(&-v));
        }
        let mean = karcher_mean(&samples, 50).unwrap();
        assert!(mean.angle_to(&centre) < 1e-9, "{}", mean.angle_to(&centre));
        // Starting far from the centre changes nothing.
        samples.rotate_left(37);
        assert!(karcher_mean(&samples, 50).unwrap().angle_to(&centre) < 1e-9);
        assert!(karcher_mean(&[], 10).is_none());
    }

    #[test]
    fn exp_and_log_are_inverse() {
        let mut rng = Rng::new(9);
        for _ in 0..200 {
            let v = Vector3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 5.0;
            let v = if v.norm() >= std::f64::consts::PI {
                v * (3.0 / v.norm())
            } else {
                v
            };
            assert!((log(&exp(&v)) - v).norm() < 1e-12);
        }
    }
}
