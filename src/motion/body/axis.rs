//! Signed coordinate axes (`y`, `-z`, …): what a take's up and forward are, and the turn
//! that takes one up axis to another.

use std::fmt;
use std::str::FromStr;

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// One of the six signed coordinate axes of a take's own coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Axis {
    /// 0 = x, 1 = y, 2 = z.
    index: u8,
    negative: bool,
}

impl Axis {
    pub const X: Axis = Axis::new(0, false);
    pub const Y: Axis = Axis::new(1, false);
    pub const Z: Axis = Axis::new(2, false);

    const fn new(index: u8, negative: bool) -> Axis {
        Axis { index, negative }
    }

    /// The axis `index` (0 = x, 1 = y, 2 = z), negated when `negative`; `None` past z.
    pub fn of(index: usize, negative: bool) -> Option<Axis> {
        (index < 3).then(|| Axis::new(index as u8, negative))
    }

    /// All six, positive ones first.
    pub fn all() -> [Axis; 6] {
        [
            Axis::X,
            Axis::Y,
            Axis::Z,
            Axis::X.flipped(),
            Axis::Y.flipped(),
            Axis::Z.flipped(),
        ]
    }

    /// The coordinate index (0 = x, 1 = y, 2 = z).
    pub fn index(self) -> usize {
        usize::from(self.index)
    }

    pub fn is_negative(self) -> bool {
        self.negative
    }

    /// +1 or −1.
    pub fn sign(self) -> f64 {
        if self.negative {
            -1.0
        } else {
            1.0
        }
    }

    /// The same axis pointing the other way.
    pub const fn flipped(self) -> Axis {
        Axis::new(self.index, !self.negative)
    }

    pub fn vector(self) -> Vector3<f64> {
        let mut v = Vector3::zeros();
        v[self.index()] = self.sign();
        v
    }

    /// The two coordinate indices across this axis (the horizontal ones when it is up).
    pub fn across(self) -> [usize; 2] {
        match self.index {
            0 => [1, 2],
            1 => [0, 2],
            _ => [0, 1],
        }
    }

    /// The signed axis nearest `v` (largest component); `None` for a zero or non-finite `v`.
    pub fn nearest(v: &Vector3<f64>) -> Option<Axis> {
        if !v.iter().all(|c| c.is_finite()) || v.norm() == 0.0 {
            return None;
        }
        let i = v.iamax();
        Axis::of(i, v[i] < 0.0)
    }

    /// The turn that takes this axis to `to`: the shortest one (a quarter turn about
    /// `self × to`), a half turn about the lowest-numbered axis across both when they are
    /// opposite, `None` when they are the same.
    pub fn turn_to(self, to: Axis) -> Option<Matrix3<f64>> {
        if self == to {
            return None;
        }
        let m = if self.index == to.index {
            let about = (0..3).find(|&i| i != self.index()).expect("three axes");
            Rotation3::from_axis_angle(
                &Unit::new_unchecked(Axis::new(about as u8, false).vector()),
                std::f64::consts::PI,
            )
        } else {
            let about = Unit::new_normalize(self.vector().cross(&to.vector()));
            Rotation3::from_axis_angle(&about, std::f64::consts::FRAC_PI_2)
        };
        // Exact: every entry of a quarter or half turn about a coordinate axis is 0 or ±1.
        Some(m.into_inner().map(f64::round))
    }

    pub fn name(self) -> &'static str {
        match (self.index, self.negative) {
            (0, false) => "x",
            (1, false) => "y",
            (2, false) => "z",
            (0, true) => "-x",
            (1, true) => "-y",
            _ => "-z",
        }
    }
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Axis {
    type Err = String;
    fn from_str(s: &str) -> Result<Axis, String> {
        let t = s.trim().to_ascii_lowercase();
        let (negative, name) = match t.strip_prefix('-') {
            Some(rest) => (true, rest),
            None => (false, t.strip_prefix('+').unwrap_or(&t)),
        };
        let index = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => {
                return Err(format!(
                    "an axis is x, y or z, signed (\"-z\"), not {:?}",
                    s.trim()
                ))
            }
        };
        Ok(Axis::new(index, negative))
    }
}

impl Serialize for Axis {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Axis {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Axis, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_print() {
        for a in Axis::all() {
            assert_eq!(a.name().parse::<Axis>().unwrap(), a);
            assert_eq!(serde_json::to_string(&a).unwrap(), format!("\"{a}\""));
        }
        assert_eq!("+Z".parse::<Axis>().unwrap(), Axis::Z);
        assert_eq!("-y".parse::<Axis>().unwrap(), Axis::Y.flipped());
        assert!("w".parse::<Axis>().is_err());
        assert!(serde_json::from_str::<Axis>("\"up\"").is_err());
        assert_eq!(Axis::all().iter().filter(|a| a.is_negative()).count(), 3);
    }

    /// Every turn is a proper rotation taking its axis where it says; Z-up to Y-up is the
    /// quarter turn about X that takes (x, y, z) to (x, z, −y).
    #[test]
    fn turns_take_one_axis_to_another() {
        for from in Axis::all() {
            for to in Axis::all() {
                match from.turn_to(to) {
                    None => assert_eq!(from, to),
                    Some(m) => {
                        assert!((m.determinant() - 1.0).abs() < 1e-12, "{from}→{to}");
                        assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-12);
                        assert_eq!(m * from.vector(), to.vector(), "{from}→{to}");
                    }
                }
            }
        }
        let m = Axis::Z.turn_to(Axis::Y).unwrap();
        assert_eq!(
            m * Vector3::new(1.0, 2.0, 3.0),
            Vector3::new(1.0, 3.0, -2.0)
        );
        assert_eq!(
            Axis::nearest(&Vector3::new(0.1, -0.9, 0.3)),
            Some(Axis::Y.flipped())
        );
        assert_eq!(Axis::nearest(&Vector3::zeros()), None);
    }
}
