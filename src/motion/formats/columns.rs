//! Sampled channels out (analog answers): rows of named columns at one rate, as JSON, CSV,
//! NPY (`<f8`, `rows × channels`) or bare little-endian f32.

use serde::Serialize;

use super::Format;
use crate::motion::error::{Error, Result};

/// One column: its label and unit.
#[derive(Debug, Clone, Serialize)]
pub struct Column {
    pub label: String,
    pub unit: String,
}

/// Rows of `columns.len()` values each (row-major), sampled at `rate` from `t0` seconds.
pub struct Columns<'a> {
    pub rate: f64,
    pub t0: f64,
    pub columns: &'a [Column],
    pub values: &'a [f64],
}

impl Columns<'_> {
    fn rows(&self) -> usize {
        self.values.len() / self.columns.len().max(1)
    }
}

/// The columns in `format` (JSON, CSV, NPY or F32); others are refused.
pub fn write(c: &Columns<'_>, format: Format) -> Result<Vec<u8>> {
    let w = c.columns.len().max(1);
    match format {
        Format::Json => {
            #[derive(Serialize)]
            struct Json<'a> {
                rate: f64,
                t0: f64,
                samples: usize,
                channels: &'a [Column],
                /// Rows; a value that is not a number is `null`.
                values: Vec<Vec<Option<f64>>>,
            }
            let values = c
                .values
                .chunks(w)
                .map(|r| r.iter().map(|v| v.is_finite().then_some(*v)).collect())
                .collect();
            serde_json::to_vec(&Json {
                rate: c.rate,
                t0: c.t0,
                samples: c.rows(),
                channels: c.columns,
                values,
            })
            .map_err(|e| Error::Invalid(e.to_string()))
        }
        Format::Csv => {
            use std::fmt::Write;
            let mut s = String::from("time_s");
            for col in c.columns {
                let name = if col.unit.is_empty() {
                    col.label.clone()
                } else {
                    format!("{} ({})", col.label, col.unit)
                };
                let _ = write!(s, ",\"{}\"", name.replace('"', "\"\""));
            }
            s.push('\n');
            for (i, row) in c.values.chunks(w).enumerate() {
                let _ = write!(s, "{}", c.t0 + i as f64 / c.rate);
                for v in row {
                    if v.is_finite() {
                        let _ = write!(s, ",{v}");
                    } else {
                        s.push(',');
                    }
                }
                s.push('\n');
            }
            Ok(s.into_bytes())
        }
        Format::Npy => {
            let dict = format!(
                "{{'descr': '<f8', 'fortran_order': False, 'shape': ({}, {}), }}",
                c.rows(),
                c.columns.len()
            );
            let mut header = dict.into_bytes();
            // Magic, version, length, then the dict padded so the data starts at 64k + 64.
            let unpadded = 10 + header.len() + 1;
            header.resize(
                header.len() + unpadded.next_multiple_of(64) - unpadded,
                b' ',
            );
            header.push(b'\n');
            let mut out = Vec::with_capacity(10 + header.len() + c.values.len() * 8);
            out.extend_from_slice(b"\x93NUMPY\x01\x00");
            out.extend_from_slice(&(header.len() as u16).to_le_bytes());
            out.extend_from_slice(&header);
            for v in c.values {
                out.extend_from_slice(&v.to_le_bytes());
            }
            Ok(out)
        }
        Format::F32 => Ok(c
            .values
            .iter()
            .flat_map(|&v| (v as f32).to_le_bytes())
            .collect()),
        f => Err(Error::Unsupported(format!(
            "analog channels are written as json, csv, npy or f32, not {f}"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_format_holds_the_values() {
        let columns = [
            Column {
                label: "Fz1".into(),
                unit: "N".into(),
            },
            Column {
                label: "EMG".into(),
                unit: "V".into(),
            },
        ];
        let values = [1.5, -2.0, 3.0, f64::NAN];
        let c = Columns {
            rate: 1000.0,
            t0: 0.5,
            columns: &columns,
            values: &values,
        };
        let json: serde_json::Value =
            serde_json::from_slice(&write(&c, Format::Json).unwrap()).unwrap();
        assert_eq!(json["values"][1][0], 3.0);
        assert!(json["values"][1][1].is_null());
        let csv = String::from_utf8(write(&c, Format::Csv).unwrap()).unwrap();
        assert_eq!(csv.lines().nth(2).unwrap(), "0.501,3,");
        let npy = write(&c, Format::Npy).unwrap();
        assert_eq!((npy.len() - values.len() * 8) % 64, 0);
        assert_eq!(
            &npy[npy.len() - 16..npy.len() - 8],
            3.0f64.to_le_bytes().as_slice()
        );
        assert_eq!(write(&c, Format::F32).unwrap().len(), 16);
        assert!(write(&c, Format::Bvh).is_err());
    }
}
