//! Codec identifiers, error bounds and latency classes: the words a user states.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::error::{Error, Result};
use super::{CodecId, Target};

/// Declares [`CodecId`] and [`super::codec`] from the registry's table in `codec/mod.rs`,
/// one line per codec: variant = the byte written in bitstreams, its name, its latency
/// class, and its implementation (point codecs) — so adding a codec is its own module and
/// one line there.
macro_rules! registry {
    (
        points: { $( $(#[$pm:meta])* $p:ident = $pb:literal, $pn:literal, $pl:ident => $imp:expr; )* }
        analog: { $( $(#[$am:meta])* $a:ident = $ab:literal, $an:literal, $al:ident; )* }
    ) => {
        /// Every codec the container format knows. The numeric value is written in
        /// bitstreams: never reuse one.
        #[derive(
            Debug, Clone, Copy, PartialEq, Eq, Hash,
            serde::Serialize, serde::Deserialize, PartialOrd, Ord,
        )]
        #[serde(rename_all = "kebab-case")]
        pub enum CodecId {
            $( $(#[$pm])* $p = $pb, )*
            $( $(#[$am])* $a = $ab, )*
        }

        impl CodecId {
            /// The codecs of points (and skeletons), in registry order.
            pub const ALL: [CodecId; [$(CodecId::$p),*].len()] = [$(CodecId::$p),*];

            /// The codecs of analog channels: never candidates for a take's points.
            pub const ANALOG: [CodecId; [$(CodecId::$a),*].len()] = [$(CodecId::$a),*];

            pub fn name(self) -> &'static str {
                match self {
                    $( CodecId::$p => $pn, )*
                    $( CodecId::$a => $an, )*
                }
            }

            /// How many frames a decoder must see before it can emit the first one.
            pub fn latency(self) -> $crate::codec::Latency {
                match self {
                    $( CodecId::$p => $crate::codec::Latency::$pl, )*
                    $( CodecId::$a => $crate::codec::Latency::$al, )*
                }
            }
        }

        /// The implementation of a point codec.
        pub fn codec(id: CodecId) -> Result<&'static dyn Codec> {
            match id {
                $( CodecId::$p => Ok(&$imp), )*
                $( CodecId::$a )|* => Err(Error::Invalid(format!(
                    "{id} codes analog channels, not points"
                ))),
            }
        }
    };
}
pub(super) use registry;

impl CodecId {
    /// Whether this codec codes analog channels rather than points.
    pub fn is_analog(self) -> bool {
        CodecId::ANALOG.contains(&self)
    }

    pub fn from_byte(b: u8) -> Option<CodecId> {
        CodecId::ALL
            .into_iter()
            .chain(CodecId::ANALOG)
            .find(|c| *c as u8 == b)
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
            .chain(CodecId::ANALOG)
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

/// The max bound a mean bound gets when the request states no max: this many times the
/// mean. Why 10: a mean bound alone let truncating codecs (PCA, DCT) serve a hand 70 cm
/// from where it was under "mean 3 mm" — an error the papers' mean hides and no archive may
/// serve. Errors that are noise-like never come near 10× their mean (an isotropic Gaussian
/// error's largest of a million samples is about 3.5× its mean; uniform quantisation's is
/// never more than 1.8×),
/// so the cap leaves the codecs' mean-bound savings alone and binds only on outliers —
/// the structured misses it is there to stop. At mean 3 mm it allows 3 cm, under a
/// marker's spacing on a limb.
pub const DEFAULT_MAX_PER_MEAN: f64 = 10.0;

/// The fidelity a user asks for, in millimetres, judged on decoded output: every sample
/// within the max bound, and, when one is asked for, the mean Euclidean error within the
/// mean bound. There is always a max: a mean bound alone gets
/// [`DEFAULT_MAX_PER_MEAN`] × the mean ([`ErrorBound::mean`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ErrorBound {
    max_mm: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    mean_mm: Option<f64>,
}

impl ErrorBound {
    /// Every sample within `mm`. Unchecked: for bounds the code states; what a client
    /// states goes through [`ErrorBound::from_request`].
    pub const fn max(mm: f64) -> Self {
        ErrorBound {
            max_mm: mm,
            mean_mm: None,
        }
    }

    /// A mean of `mm` with the default max cap ([`ErrorBound::default_cap`]). Unchecked.
    pub fn mean(mm: f64) -> Self {
        ErrorBound {
            max_mm: ErrorBound::default_cap(mm),
            mean_mm: Some(mm),
        }
    }

    /// Both bounds. Unchecked.
    pub const fn both(max_mm: f64, mean_mm: f64) -> Self {
        ErrorBound {
            max_mm,
            mean_mm: Some(mean_mm),
        }
    }

    /// The max a mean bound of `mean_mm` gets when none is asked for: [`DEFAULT_MAX_PER_MEAN`]
    /// times it, within the loosest bound a client may state.
    pub fn default_cap(mean_mm: f64) -> f64 {
        (DEFAULT_MAX_PER_MEAN * mean_mm).min(crate::limits::MAX_BOUND_MM.max(mean_mm))
    }

    pub fn max_mm(self) -> f64 {
        self.max_mm
    }

    pub fn mean_mm(self) -> Option<f64> {
        self.mean_mm
    }

    /// Whether the max is the default cap of the mean bound (said so where it is shown).
    pub fn max_is_default(self) -> bool {
        self.mean_mm
            .is_some_and(|m| self.max_mm == ErrorBound::default_cap(m))
    }

    /// The tighter of the two: the bound a codec that cannot aim at a mean holds every
    /// sample to (a mean is then met too).
    pub fn tightest_mm(self) -> f64 {
        self.mean_mm.map_or(self.max_mm, |m| m.min(self.max_mm))
    }

    /// A bound as it is stored: both fields checked, `None` for a mean not asked for.
    pub fn from_stored(max_mm: f64, mean_mm: Option<f64>) -> Result<Self> {
        Ok(ErrorBound {
            max_mm: check_mm(max_mm)?,
            mean_mm: mean_mm.map(check_mm).transpose()?,
        })
    }

    /// The bound a request states with its two optional fields (`max_error_mm`,
    /// `mean_error_mm`): either or both; a max of [`DEFAULT_BOUND_MM`] when neither is
    /// given, the default cap when only a mean is.
    pub fn from_request(max_mm: Option<f64>, mean_mm: Option<f64>) -> Result<Self> {
        let mean_mm = mean_mm.map(check_mm).transpose()?;
        let max_mm = match (max_mm, mean_mm) {
            (Some(v), _) => check_mm(v)?,
            (None, Some(m)) => ErrorBound::default_cap(m),
            (None, None) => DEFAULT_BOUND_MM,
        };
        Ok(ErrorBound { max_mm, mean_mm })
    }

    /// The bound in a take's units (`mm_per_unit` millimetres each), a hair inside
    /// ([`BOUND_MARGIN`]): what encoders aim at.
    pub fn target(self, mm_per_unit: f64) -> Target {
        let units = |mm: f64| mm / mm_per_unit * BOUND_MARGIN;
        Target {
            max: units(self.max_mm),
            mean: self.mean_mm.map(units),
        }
    }

    /// Whether measured errors (mm) satisfy the bound.
    pub fn holds(self, max_mm: f64, mean_mm: f64) -> bool {
        max_mm <= self.max_mm && self.mean_mm.is_none_or(|m| mean_mm <= m)
    }
}

impl fmt::Display for ErrorBound {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.mean_mm {
            None => write!(f, "max {} mm", self.max_mm),
            Some(m) if self.max_is_default() => write!(
                f,
                "mean {m} mm with max {} mm (the default cap, {DEFAULT_MAX_PER_MEAN}× the mean)",
                self.max_mm
            ),
            Some(m) => write!(f, "mean {m} mm with max {} mm", self.max_mm),
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
        for c in CodecId::ALL.into_iter().chain(CodecId::ANALOG) {
            assert_eq!(c.name().parse::<CodecId>().unwrap(), c);
            assert_eq!(CodecId::from_byte(c as u8), Some(c));
            // The API's spelling (serde) is the registry's name.
            assert_eq!(serde_json::to_value(c).unwrap(), c.name());
            assert_eq!(super::super::codec(c).is_ok(), !c.is_analog(), "{c}");
        }
        // Bytes written in bitstreams, and the latency classes choice filters on: each
        // codec's are pinned (a new codec adds its own, never another's byte).
        use CodecId::*;
        use Latency::{Clip, Frame, Sequence};
        for (c, byte, latency) in [
            (Raw, 1, Frame),
            (Quant, 2, Frame),
            (Mdtt, 3, Sequence),
            (LsdtClip, 4, Clip),
            (LsdtFrame, 5, Frame),
            (Spca, 6, Sequence),
            (Pga, 7, Sequence),
            (MdttShared, 8, Sequence),
            (BvhLossless, 9, Frame),
            (Rot, 10, Frame),
            (AnalogLossless, 11, Frame),
            (AnalogBounded, 12, Frame),
        ] {
            assert_eq!((c as u8, c.latency()), (byte, latency), "{c}");
        }
        let mut bytes: Vec<u8> = CodecId::ALL
            .into_iter()
            .chain(CodecId::ANALOG)
            .map(|c| c as u8)
            .collect();
        bytes.sort_unstable();
        bytes.dedup();
        assert_eq!(bytes.len(), CodecId::ALL.len() + CodecId::ANALOG.len());
        assert!("zip".parse::<CodecId>().is_err());
        assert!(ErrorBound::from_request(Some(-1.0), None).is_err());
        assert!(ErrorBound::from_request(None, Some(f64::NAN)).is_err());
        assert!(Latency::Frame < Latency::Sequence);
    }

    #[test]
    fn a_bound_always_has_a_max_and_a_mean_alone_gets_the_default_cap() {
        assert_eq!(
            ErrorBound::from_request(None, None).unwrap(),
            ErrorBound::max(1.0)
        );
        let capped = ErrorBound::from_request(None, Some(3.0)).unwrap();
        assert_eq!(capped, ErrorBound::mean(3.0));
        assert_eq!((capped.max_mm(), capped.mean_mm()), (30.0, Some(3.0)));
        assert!(capped.max_is_default());
        assert!(capped.to_string().contains("default cap"), "{capped}");
        let both = ErrorBound::from_request(Some(5.0), Some(3.0)).unwrap();
        assert_eq!(both, ErrorBound::both(5.0, 3.0));
        assert!(!both.max_is_default());
        assert_eq!(both.tightest_mm(), 3.0);
        // Both must hold: a take within the mean but past the max does not meet it.
        assert!(capped.holds(30.0, 3.0));
        assert!(!capped.holds(30.1, 1.0));
        assert!(!capped.holds(10.0, 3.1));
        assert!(ErrorBound::from_request(Some(1.0), Some(-1.0)).is_err());
        // The cap stays within the loosest bound a client may state.
        let loose = ErrorBound::from_request(None, Some(crate::limits::MAX_BOUND_MM)).unwrap();
        assert_eq!(loose.max_mm(), crate::limits::MAX_BOUND_MM);
        // Stored bounds parse with the same checks.
        assert_eq!(ErrorBound::from_stored(30.0, Some(3.0)).unwrap(), capped);
        assert!(ErrorBound::from_stored(0.0, None).is_err());
        // Encoders aim a hair inside: 1 mm in a take stored in cm is just under 0.1 units.
        let t = ErrorBound::both(1.0, 0.5).target(10.0);
        assert!(t.max < 0.1 && t.max > 0.1 * (1.0 - 1e-5), "{t:?}");
        assert!(t.mean.is_some_and(|m| m < 0.05 && m > 0.05 * (1.0 - 1e-5)));
    }
}
