//! Codec identifiers, error bounds and latency classes: the words a user states.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::error::{Error, Result};
use super::Target;

/// Every codec the container format knows. The numeric value is written in bitstreams:
/// never reuse one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "kebab-case")]
pub enum CodecId {
    Raw = 1,
    Quant = 2,
    Mdtt = 3,
    LsdtClip = 4,
    LsdtFrame = 5,
    Spca = 6,
    Pga = 7,
    /// MDTT's database mode: `K` spatial bases shared by a library.
    MdttShared = 8,
    /// A skeleton's channel values exactly as the file printed them.
    BvhLossless = 9,
    /// A skeleton's rotations, error-bounded on the FK positions.
    Rot = 10,
}

impl CodecId {
    pub const ALL: [CodecId; 10] = [
        CodecId::Raw,
        CodecId::Quant,
        CodecId::Mdtt,
        CodecId::LsdtClip,
        CodecId::LsdtFrame,
        CodecId::Spca,
        CodecId::Pga,
        CodecId::MdttShared,
        CodecId::BvhLossless,
        CodecId::Rot,
    ];

    pub fn name(self) -> &'static str {
        match self {
            CodecId::Raw => "raw",
            CodecId::Quant => "quant",
            CodecId::Mdtt => "mdtt",
            CodecId::LsdtClip => "lsdt-clip",
            CodecId::LsdtFrame => "lsdt-frame",
            CodecId::Spca => "spca",
            CodecId::Pga => "pga",
            CodecId::MdttShared => "mdtt-shared",
            CodecId::BvhLossless => "bvh-lossless",
            CodecId::Rot => "rot",
        }
    }

    pub fn from_byte(b: u8) -> Option<CodecId> {
        CodecId::ALL.into_iter().find(|c| *c as u8 == b)
    }

    /// How many frames a decoder must see before it can emit the first one.
    pub fn latency(self) -> Latency {
        match self {
            CodecId::Raw
            | CodecId::Quant
            | CodecId::LsdtFrame
            | CodecId::BvhLossless
            | CodecId::Rot => Latency::Frame,
            CodecId::LsdtClip => Latency::Clip,
            CodecId::Mdtt | CodecId::MdttShared | CodecId::Spca | CodecId::Pga => Latency::Sequence,
        }
    }
}

impl fmt::Display for CodecId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for CodecId {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        CodecId::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                let names: Vec<_> = CodecId::ALL.iter().map(|c| c.name()).collect();
                Error::Invalid(format!("unknown codec {s:?}; known: {}", names.join(", ")))
            })
    }
}

/// Latency classes, ordered: a codec fits a request if its class is at most the requested.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Latency {
    Frame,
    Clip,
    Sequence,
}

impl FromStr for Latency {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "frame" => Ok(Latency::Frame),
            "clip" => Ok(Latency::Clip),
            "sequence" | "any" => Ok(Latency::Sequence),
            other => Err(Error::Invalid(format!(
                "unknown latency {other:?}; use frame, clip, sequence or any"
            ))),
        }
    }
}

/// Encoders aim a hair inside the bound so that converting their error to millimetres
/// (a multiplication that can round up) never crosses it.
pub const BOUND_MARGIN: f64 = 1.0 - 1e-6;

/// The bound when a request states none: a max error of 1 mm.
pub const DEFAULT_BOUND_MM: f64 = 1.0;

/// The fidelity a user asks for, in millimetres, judged on decoded output.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorBound {
    /// No sample farther than this from the original.
    MaxMm(f64),
    /// Mean Euclidean error at most this.
    MeanMm(f64),
}

impl ErrorBound {
    pub fn new_max(mm: f64) -> Result<Self> {
        check_mm(mm).map(ErrorBound::MaxMm)
    }

    pub fn new_mean(mm: f64) -> Result<Self> {
        check_mm(mm).map(ErrorBound::MeanMm)
    }

    pub fn mm(self) -> f64 {
        match self {
            ErrorBound::MaxMm(v) | ErrorBound::MeanMm(v) => v,
        }
    }

    /// `max` or `mean`: how the bound is named where it is stored ([`ErrorBound::from_kind`]).
    pub fn kind(self) -> &'static str {
        match self {
            ErrorBound::MaxMm(_) => "max",
            ErrorBound::MeanMm(_) => "mean",
        }
    }

    /// A bound from its stored [`kind`](ErrorBound::kind) and millimetres.
    pub fn from_kind(kind: &str, mm: f64) -> Result<Self> {
        match kind {
            "max" => ErrorBound::new_max(mm),
            "mean" => ErrorBound::new_mean(mm),
            other => Err(Error::Invalid(format!(
                "unknown bound kind {other:?}; use max or mean"
            ))),
        }
    }

    /// The bound a request states with its two optional fields (`max_error_mm`,
    /// `mean_error_mm`): at most one of them, and a max of 1 mm when neither is given.
    pub fn from_request(max_mm: Option<f64>, mean_mm: Option<f64>) -> Result<Self> {
        match (max_mm, mean_mm) {
            (Some(_), Some(_)) => Err(Error::Invalid(
                "give max_error_mm or mean_error_mm, not both".into(),
            )),
            (Some(v), None) => ErrorBound::new_max(v),
            (None, Some(v)) => ErrorBound::new_mean(v),
            (None, None) => Ok(ErrorBound::MaxMm(DEFAULT_BOUND_MM)),
        }
    }

    /// The bound in a take's units (`mm_per_unit` millimetres each), a hair inside
    /// ([`BOUND_MARGIN`]): what encoders aim at.
    pub fn in_units(self, mm_per_unit: f64) -> f64 {
        self.mm() / mm_per_unit * BOUND_MARGIN
    }

    /// [`ErrorBound::in_units`] as an encoder's target of the same kind.
    pub fn target(self, mm_per_unit: f64) -> Target {
        let units = self.in_units(mm_per_unit);
        match self {
            ErrorBound::MaxMm(_) => Target::Max(units),
            ErrorBound::MeanMm(_) => Target::Mean(units),
        }
    }

    /// Whether measured errors (mm) satisfy the bound.
    pub fn holds(self, max_mm: f64, mean_mm: f64) -> bool {
        match self {
            ErrorBound::MaxMm(b) => max_mm <= b,
            ErrorBound::MeanMm(b) => mean_mm <= b,
        }
    }
}

impl fmt::Display for ErrorBound {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ErrorBound::MaxMm(v) => write!(f, "max {v} mm"),
            ErrorBound::MeanMm(v) => write!(f, "mean {v} mm"),
        }
    }
}

fn check_mm(mm: f64) -> Result<f64> {
    let most = crate::limits::MAX_BOUND_MM;
    if mm.is_finite() && mm > 0.0 && mm <= most {
        Ok(mm)
    } else {
        Err(Error::Invalid(format!(
            "an error bound must be a number of millimetres in (0, {most}], got {mm}"
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bytes_are_stable() {
        for c in CodecId::ALL {
            assert_eq!(c.name().parse::<CodecId>().unwrap(), c);
            assert_eq!(CodecId::from_byte(c as u8), Some(c));
        }
        assert_eq!(CodecId::Mdtt as u8, 3);
        assert!("zip".parse::<CodecId>().is_err());
        assert!(ErrorBound::new_max(-1.0).is_err());
        assert!(ErrorBound::new_mean(f64::NAN).is_err());
        assert!(Latency::Frame < Latency::Sequence);
    }

    #[test]
    fn a_bound_is_named_parsed_and_aimed_at_in_one_place() {
        for b in [ErrorBound::MaxMm(0.5), ErrorBound::MeanMm(2.0)] {
            assert_eq!(ErrorBound::from_kind(b.kind(), b.mm()).unwrap(), b);
        }
        assert!(ErrorBound::from_kind("median", 1.0).is_err());
        assert_eq!(
            ErrorBound::from_request(None, None).unwrap(),
            ErrorBound::MaxMm(1.0)
        );
        assert_eq!(
            ErrorBound::from_request(None, Some(3.0)).unwrap(),
            ErrorBound::MeanMm(3.0)
        );
        assert!(ErrorBound::from_request(Some(1.0), Some(1.0)).is_err());
        assert!(ErrorBound::from_request(Some(-1.0), None).is_err());
        // Encoders aim a hair inside: 1 mm in a take stored in cm is just under 0.1 units.
        let t = ErrorBound::MaxMm(1.0).in_units(10.0);
        assert!(t < 0.1 && t > 0.1 * (1.0 - 1e-5), "{t}");
        assert_eq!(ErrorBound::MeanMm(1.0).target(10.0), Target::Mean(t));
    }
}
