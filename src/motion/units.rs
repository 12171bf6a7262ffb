//! Physical units of stored coordinates.
//!
//! Every error the product reports is in millimetres, so each take must know how many metres
//! one stored unit is. Files either declare it (C3D `POINT:UNITS`, TRC `Units`, JSON `unit`),
//! the user states it, or — for BVH, which has no unit field — we infer it from the height
//! of the figure and say so.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::error::{Error, Result};

/// Named units, with the CMU skeleton unit that the CMU BVH exports use
/// (1 unit = 0.056444 m, the ASF length factor `(1.0/0.45)*2.54/100`).
const NAMED: &[(&str, f64)] = &[
    ("m", 1.0),
    ("cm", 0.01),
    ("mm", 0.001),
    ("in", 0.0254),
    ("ft", 0.3048),
    ("cmu", 0.056_444),
];

/// The height of a standing adult, used to infer units; the figure is snapped to the nearest
/// named unit, so this only has to be right within a factor of ~1.5.
const TYPICAL_HEIGHT_M: f64 = 1.7;

/// How we came to know the unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "detail", rename_all = "snake_case")]
pub enum UnitSource {
    /// Declared in the file itself.
    Declared,
    /// Stated by the user (overrides the file).
    Explicit,
    /// Guessed; the string says from what.
    Inferred(String),
}

/// Metres per stored unit, and where that number came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Unit {
    pub metres_per_unit: f64,
    pub source: UnitSource,
}

impl Unit {
    /// A unit of `metres_per_unit` metres, within [`crate::limits::UNIT_METRES`] (a
    /// micrometre to a kilometre): outside it, errors in millimetres overflow or vanish.
    pub fn new(metres_per_unit: f64, source: UnitSource) -> Result<Self> {
        let range = crate::limits::UNIT_METRES;
        if !range.contains(&metres_per_unit) {
            return Err(Error::Invalid(format!(
                "unit must be between {:e} and {:e} metres, got {metres_per_unit:e}",
                range.start(),
                range.end()
            )));
        }
        Ok(Unit {
            metres_per_unit,
            source,
        })
    }

    pub fn millimetres() -> Self {
        Unit {
            metres_per_unit: 0.001,
            source: UnitSource::Declared,
        }
    }

    /// Multiply a distance in stored units by this to get millimetres.
    pub fn to_mm(&self) -> f64 {
        self.metres_per_unit * 1000.0
    }

    pub fn is_inferred(&self) -> bool {
        matches!(self.source, UnitSource::Inferred(_))
    }

    /// The short name if this is one of the named units, else the number of metres.
    pub fn name(&self) -> String {
        unit_name(self.metres_per_unit)
    }

    /// Infer the unit from a figure height measured in stored units.
    pub fn infer_from_height(height_units: f64) -> Option<Self> {
        if !(height_units.is_finite() && height_units > 0.0) {
            return None;
        }
        let wanted = TYPICAL_HEIGHT_M / height_units;
        let (name, m) = NAMED
            .iter()
            .copied()
            .min_by(|a, b| {
                let da = (a.1 / wanted).ln().abs();
                let db = (b.1 / wanted).ln().abs();
                da.total_cmp(&db)
            })
            .expect("NAMED is not empty");
        Some(Unit {
            metres_per_unit: m,
            source: UnitSource::Inferred(format!(
                "figure height {height_units:.3} units; nearest named unit for a {TYPICAL_HEIGHT_M} m person is {name} ({:.2} m tall)",
                height_units * m
            )),
        })
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())?;
        if self.is_inferred() {
            f.write_str(" (inferred)")?;
        }
        Ok(())
    }
}

/// `"mm"` for 0.001 etc., or the number of metres for anything else.
pub fn unit_name(metres_per_unit: f64) -> String {
    NAMED
        .iter()
        .find(|(_, m)| (m / metres_per_unit - 1.0).abs() < 1e-9)
        .map(|(n, _)| n.to_string())
        .unwrap_or_else(|| format!("{metres_per_unit}m"))
}

/// Parse a unit as written by a user or a file: a name (`mm`, `cm`, `m`, `in`, `inch`, `ft`,
/// `cmu`, and long forms) or a positive number of metres per unit.
pub fn parse_unit(text: &str) -> Result<f64> {
    let t = text.trim().trim_matches('\0').trim().to_ascii_lowercase();
    let name = match t.as_str() {
        "millimeter" | "millimeters" | "millimetre" | "millimetres" => "mm",
        "centimeter" | "centimeters" | "centimetre" | "centimetres" => "cm",
        "meter" | "meters" | "metre" | "metres" => "m",
        "inch" | "inches" | "\"" => "in",
        "foot" | "feet" => "ft",
        other => other,
    };
    if let Some((_, m)) = NAMED.iter().find(|(n, _)| *n == name) {
        return Ok(*m);
    }
    match name.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => {
            Unit::new(v, UnitSource::Explicit).map(|u| u.metres_per_unit)
        }
        _ => Err(Error::Invalid(format!(
            "unknown unit {text:?}: use mm, cm, m, in, ft, cmu or metres per unit as a number"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_beyond_physical_scale_are_refused() {
        // unit=1e308 once reached the codecs, which decoded NaN (a 500).
        for bad in ["1e308", "1e-300", "5000", "0", "-1", "inf", "nan"] {
            assert!(parse_unit(bad).is_err(), "{bad}");
        }
        assert_eq!(parse_unit("0.001").unwrap(), 0.001);
        assert_eq!(parse_unit("1000").unwrap(), 1000.0);
        assert!(Unit::new(1e308, UnitSource::Declared).is_err());
    }

    #[test]
    fn infers_corpus_units_from_height() {
        // Bandai figures are ~170 cm, CMU ~30 units, a Vicon export ~1.8 m, a C3D-like 1750 mm.
        assert_eq!(Unit::infer_from_height(172.0).unwrap().name(), "cm");
        assert_eq!(Unit::infer_from_height(30.5).unwrap().name(), "cmu");
        assert_eq!(Unit::infer_from_height(1.8).unwrap().name(), "m");
        assert_eq!(Unit::infer_from_height(1750.0).unwrap().name(), "mm");
        assert_eq!(Unit::infer_from_height(68.0).unwrap().name(), "in");
        assert!(Unit::infer_from_height(0.0).is_none());
        assert!(Unit::infer_from_height(f64::NAN).is_none());
    }

    #[test]
    fn parses_names_and_numbers() {
        assert_eq!(parse_unit("mm").unwrap(), 0.001);
        assert_eq!(parse_unit(" Millimeters ").unwrap(), 0.001);
        assert_eq!(parse_unit("0.056444").unwrap(), 0.056444);
        assert!(parse_unit("-1").is_err());
        assert!(parse_unit("furlong").is_err());
        assert_eq!(Unit::new(0.01, UnitSource::Explicit).unwrap().to_mm(), 10.0);
        assert!(Unit::new(f64::NAN, UnitSource::Explicit).is_err());
    }
}
