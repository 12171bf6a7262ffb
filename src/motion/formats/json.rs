//! JSON point arrays: `{"fps": 120, "unit": "mm", "points": ["a", …],
//! "frames": [[[x, y, z], …], …]}`; a missing sample is `null`. `unit` may be a name or a
//! number of metres per unit and may be omitted (then it is inferred). An optional
//! `"labels": {"content": "walk", …}` labels the take ([`crate::labels`]).

use serde::Deserialize;

use super::writer::{push_f32, write_whole, FrameWriter, Shape, TEXT_VALUE_BYTES};
use super::{perr, unsettled_unit, Format, Parsed, ReadLimits};
use crate::motion::error::{Error, Location, Result};
use crate::motion::model::Motion;
use crate::motion::units::{parse_unit, unit_name};

#[derive(Deserialize)]
#[serde(untagged)]
enum UnitField {
    Name(String),
    Metres(f64),
}

#[derive(Deserialize)]
struct Doc {
    fps: f64,
    #[serde(default)]
    unit: Option<UnitField>,
    points: Vec<String>,
    frames: Vec<Vec<Option<[f32; 3]>>>,
    #[serde(default)]
    labels: Option<serde_json::Value>,
}

fn err(at: Location, reason: impl Into<String>) -> Error {
    perr(Format::Json, at, reason)
}

pub(crate) fn read(bytes: &[u8], limits: &ReadLimits) -> Result<Parsed> {
    let doc: Doc = serde_json::from_slice(bytes).map_err(|e| {
        err(
            Location::Line(e.line()),
            format!("{e} (expected {{fps, unit, points, frames:[[[x,y,z],…],…]}})"),
        )
    })?;
    limits.check_shape(doc.frames.len(), doc.points.len())?;
    let n = doc.points.len();
    let mut positions = Vec::with_capacity(doc.frames.len() * n * 3);
    for (f, frame) in doc.frames.iter().enumerate() {
        if frame.len() != n {
            return Err(err(
                Location::Whole,
                format!("frame {f} has {} points, \"points\" names {n}", frame.len()),
            ));
        }
        for p in frame {
            positions.extend_from_slice(&p.unwrap_or([f32::NAN; 3]));
        }
    }
    let declared_unit = match doc.unit {
        None => None,
        Some(UnitField::Name(s)) => Some(parse_unit(&s)?),
        Some(UnitField::Metres(m)) => Some(parse_unit(&m.to_string())?),
    };
    let labels = match &doc.labels {
        None => Default::default(),
        Some(v) => crate::labels::Labels::from_json(v).map_err(|e| err(Location::Whole, e))?,
    };
    let motion = if n == 0 {
        Motion::without_points(doc.fps, unsettled_unit(), doc.frames.len())?
    } else {
        Motion::new(doc.fps, unsettled_unit(), doc.points, positions, None)?
    };
    Ok(Parsed {
        motion,
        declared_unit,
        warnings: Vec::new(),
        // JSON has no NaN or infinity, and serde refuses a number past f32 as out of
        // range: what parses is finite.
        contradictions: Vec::new(),
        extras: super::Extras {
            labels,
            ..Default::default()
        },
    })
}

/// Write as JSON; coordinates in the take's own unit, named in `unit`.
pub fn write(motion: &Motion) -> Vec<u8> {
    write_with(motion, serde_json::Map::new())
}

/// [`write`] with more top-level fields beside the document's own (a range response says
/// which take and frames it holds); readers ignore them, so the result reads back as a take.
pub fn write_with(motion: &Motion, fields: serde_json::Map<String, serde_json::Value>) -> Vec<u8> {
    write_whole(
        Box::new(Writer::new(Shape::of(motion), fields)),
        motion.frame_count(),
        motion.positions(),
    )
}

/// The JSON document frame by frame: the header's fields, then `"frames":[` and a frame
/// per block value, then `]}`.
pub struct Writer {
    shape: Shape,
    fields: serde_json::Map<String, serde_json::Value>,
    written: usize,
}

impl Writer {
    pub fn new(shape: Shape, fields: serde_json::Map<String, serde_json::Value>) -> Writer {
        Writer {
            shape,
            fields,
            written: 0,
        }
    }
}

impl FrameWriter for Writer {
    fn head(&mut self, out: &mut Vec<u8>) {
        let m = self.shape.unit.metres_per_unit;
        let name = unit_name(m);
        // Named units as their name, anything else as a number of metres.
        let unit = if parse_unit(&name).is_ok() {
            serde_json::Value::from(name)
        } else {
            serde_json::Value::from(m)
        };
        let mut fields = std::mem::take(&mut self.fields);
        fields.insert("fps".into(), self.shape.fps.into());
        fields.insert("unit".into(), unit);
        fields.insert("points".into(), self.shape.point_names.to_vec().into());
        let header = serde_json::Value::Object(fields).to_string();
        out.extend_from_slice(&header.as_bytes()[..header.len() - 1]);
        out.extend_from_slice(b",\"frames\":[");
    }

    /// Frames are written by hand: serde_json would print f32 through f64 with noise digits.
    fn frames(&mut self, n: usize, values: &[f32], out: &mut Vec<u8>) {
        let w = self.shape.width();
        for f in 0..n {
            let frame = &values[f * w..(f + 1) * w];
            if self.written > 0 {
                out.push(b',');
            }
            self.written += 1;
            out.push(b'[');
            for (i, p) in frame.chunks_exact(3).enumerate() {
                if i > 0 {
                    out.push(b',');
                }
                if p[0].is_nan() {
                    out.extend_from_slice(b"null");
                } else {
                    out.push(b'[');
                    for (k, v) in p.iter().enumerate() {
                        if k > 0 {
                            out.push(b',');
                        }
                        push_f32(out, *v, "null");
                    }
                    out.push(b']');
                }
            }
            out.push(b']');
        }
    }

    fn tail(&mut self, out: &mut Vec<u8>) {
        out.extend_from_slice(b"]}\n");
    }

    fn frame_bytes(&self) -> usize {
        self.shape.point_names.len() * (3 * TEXT_VALUE_BYTES + 3) + 3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_gaps_and_units() {
        let doc = br#"{"fps": 60, "unit": "cm", "points": ["a","b"],
            "frames": [[[1,2,3], null], [[4,5,6],[7,8,9.5]]]}"#;
        let p = read(doc, &ReadLimits::default()).unwrap();
        assert_eq!(p.declared_unit, Some(0.01));
        assert_eq!(p.motion.gap_count(), 1);
        assert_eq!(p.motion.sample(1, 1), Some([7.0, 8.0, 9.5]));
    }

    #[test]
    fn shape_errors_are_clear() {
        let doc = br#"{"fps": 60, "points": ["a"], "frames": [[[1,2,3],[4,5,6]]]}"#;
        let e = read(doc, &ReadLimits::default()).unwrap_err().to_string();
        assert!(e.contains("frame 0 has 2 points"), "{e}");
        assert!(read(br#"{"fps": 60"#, &ReadLimits::default()).is_err());
        assert!(read(
            br#"{"fps": -1, "points": [], "frames": []}"#,
            &ReadLimits::default()
        )
        .is_err());
    }
}
