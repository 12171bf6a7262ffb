//! TRC (Motion Analysis / OpenSim marker trajectories): five tab-separated header lines,
//! then `Frame#, Time, X1, Y1, Z1, …` rows. A blank cell is a missing sample.
//!
//! Real files disagree with their own headers (a `NumMarkers` of 0 above rows of data, rows
//! cut short after the last visible marker), so the rows decide and the header only warns.

use std::io::Write as _;

use super::text::{as_text, numbered_lines};
use super::writer::{push_f32, FrameWriter, Shape, TEXT_VALUE_BYTES};
use super::{perr, unsettled_unit, Format, Parsed, ReadLimits};
use crate::motion::error::{Error, Location, Result};
use crate::motion::model::Motion;
use crate::motion::units::{parse_unit, unit_name};

const FMT: Format = Format::Trc;

fn err(line: usize, reason: impl Into<String>) -> Error {
    perr(FMT, Location::Line(line), reason)
}

fn cells(line: &str) -> Vec<&str> {
    let mut c: Vec<&str> = if line.contains('\t') {
        line.split('\t').collect()
    } else {
        line.split_ascii_whitespace().collect()
    };
    while c.last().is_some_and(|s| s.trim().is_empty()) {
        c.pop();
    }
    c
}

pub(crate) fn read(bytes: &[u8], limits: &ReadLimits) -> Result<Parsed> {
    let text = as_text(bytes);
    let mut lines = numbered_lines(&text);
    let mut seen = 0;
    let mut header = |what: &str| {
        let l = lines
            .next()
            .ok_or_else(|| err(seen.max(1), format!("file ends before the {what} line")))?;
        seen = l.0;
        Ok::<_, Error>(l)
    };
    let (n1, l1) = header("PathFileType")?;
    if !l1.trim_start().starts_with("PathFileType") {
        return Err(err(n1, "expected PathFileType"));
    }
    let (_, keys) = header("DataRate/NumFrames keys")?;
    let (nv, values) = header("header values")?;
    let (nn, names_line) = header("marker names")?;
    let (_, _axes) = header("X1/Y1/Z1 axes")?;
    let keys = cells(keys);
    let values = cells(values);
    let field = |k: &str| {
        keys.iter()
            .position(|key| key.trim().eq_ignore_ascii_case(k))
            .and_then(|i| values.get(i))
            .map(|v| v.trim())
    };
    let rate = field("DataRate")
        .or_else(|| field("CameraRate"))
        .and_then(|v| v.parse::<f64>().ok())
        .filter(|r| r.is_finite() && *r > 0.0)
        .ok_or_else(|| err(nv, "DataRate is missing or not a positive number"))?;
    let mut warnings = Vec::new();
    let unit = match field("Units") {
        Some(u) => match parse_unit(u) {
            Ok(m) => Some(m),
            Err(_) => {
                warnings.push(format!("Units {u:?} not understood; inferring"));
                None
            }
        },
        None => None,
    };
    let header_markers = field("NumMarkers").and_then(|v| v.parse::<usize>().ok());
    let header_frames = field("NumFrames").and_then(|v| v.parse::<usize>().ok());

    let name_cells = cells(names_line);
    if name_cells
        .first()
        .is_some_and(|c| !c.trim().eq_ignore_ascii_case("Frame#"))
    {
        return Err(err(nn, "expected the Frame#/Time/marker-names line"));
    }
    let mut names: Vec<String> = name_cells
        .iter()
        .skip(2)
        .step_by(3)
        .map(|s| s.trim().to_string())
        .collect();

    // Rows: cells after Frame# and Time, three per marker.
    let mut rows: Vec<(usize, Vec<&str>)> = Vec::new();
    let mut width = names.len();
    for (n, line) in lines {
        let c = cells(line);
        if c.is_empty() {
            continue;
        }
        if c.len() < 2 {
            return Err(err(n, "data row without Frame# and Time"));
        }
        width = width.max((c.len() - 2).div_ceil(3));
        limits.check_shape(rows.len() + 1, width)?;
        rows.push((n, c));
    }
    if width > names.len() {
        for i in names.len()..width {
            names.push(format!("M{}", i + 1));
        }
    }
    names.truncate(width);
    uniquify(&mut names);
    if header_markers.is_some_and(|h| h != width) {
        warnings.push(format!(
            "header says {} markers, rows hold {width}",
            header_markers.unwrap_or(0)
        ));
    }
    let mut contradictions = Vec::new();
    match header_frames {
        Some(h) if h > rows.len() => contradictions.push(format!(
            "header says {h} frames but only {} rows are present (the file is cut short)",
            rows.len()
        )),
        Some(h) if h < rows.len() => warnings.push(format!(
            "header says {h} frames, {} rows are present; loaded every row",
            rows.len()
        )),
        _ => {}
    }

    let mut positions = vec![f32::NAN; rows.len() * width * 3];
    // A blank cell is a gap; a cell that reads as NaN or ±infinity is one too, counted.
    let mut not_finite = 0usize;
    for (f, (n, c)) in rows.iter().enumerate() {
        let mut last_bad = None;
        for (k, cell) in c.iter().skip(2).enumerate() {
            let cell = cell.trim();
            if cell.is_empty() {
                continue;
            }
            let v: f32 = cell
                .parse()
                .map_err(|_| err(*n, format!("{cell:?} is not a number")))?;
            if !v.is_finite() && last_bad != Some(k / 3) {
                last_bad = Some(k / 3);
                not_finite += 1;
            }
            positions[f * width * 3 + k] = v;
        }
    }
    warnings.extend(super::non_finite_warning(not_finite));
    let motion = if width == 0 {
        Motion::without_points(rate, unsettled_unit(), rows.len())?
    } else {
        Motion::new(rate, unsettled_unit(), names, positions, None)?
    };
    Ok(Parsed {
        motion,
        declared_unit: unit,
        warnings,
        contradictions,
        extras: Default::default(),
    })
}

fn uniquify(names: &mut [String]) {
    for i in 0..names.len() {
        if names[i].is_empty() {
            names[i] = format!("M{}", i + 1);
        }
        let base = names[i].clone();
        let mut k = 2;
        while names[..i].contains(&names[i]) {
            names[i] = format!("{base}_{k}");
            k += 1;
        }
    }
}

/// TRC row by row.
pub struct Writer {
    shape: Shape,
    /// The unit the file names, and the factor from the take's unit to it.
    unit: String,
    scale: f32,
    written: usize,
}

impl Writer {
    pub fn new(shape: Shape) -> Writer {
        let (unit, scale) = match unit_name(shape.unit.metres_per_unit).as_str() {
            n @ ("mm" | "cm" | "m") => (n.to_string(), 1.0f32),
            _ => (
                "mm".to_string(),
                (shape.unit.metres_per_unit * 1000.0) as f32,
            ),
        };
        Writer {
            shape,
            unit,
            scale,
            written: 0,
        }
    }
}

impl FrameWriter for Writer {
    fn head(&mut self, out: &mut Vec<u8>) {
        let (frames, points) = (self.shape.frames, self.shape.point_names.len());
        let (fps, unit) = (self.shape.fps, &self.unit);
        let _ = writeln!(out, "PathFileType\t4\t(X/Y/Z)\tmocapstore.trc");
        let _ = writeln!(out, "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames");
        let _ = writeln!(
            out,
            "{fps}\t{fps}\t{frames}\t{points}\t{unit}\t{fps}\t1\t{frames}"
        );
        out.extend_from_slice(b"Frame#\tTime");
        for n in self.shape.point_names.iter() {
            let _ = write!(out, "\t{n}\t\t");
        }
        out.extend_from_slice(b"\n\t");
        for i in 1..=points {
            let _ = write!(out, "\tX{i}\tY{i}\tZ{i}");
        }
        out.extend_from_slice(b"\n\n");
    }

    fn frames(&mut self, n: usize, values: &[f32], out: &mut Vec<u8>) {
        let w = self.shape.width();
        for f in 0..n {
            let at = self.written;
            self.written += 1;
            let _ = write!(out, "{}\t{}", at + 1, at as f64 / self.shape.fps);
            for v in &values[f * w..(f + 1) * w] {
                out.push(b'\t');
                push_f32(out, v * self.scale, "");
            }
            out.push(b'\n');
        }
    }

    fn frame_bytes(&self) -> usize {
        48 + self.shape.width() * TEXT_VALUE_BYTES
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "PathFileType\t4\t(X/Y/Z)\tx.trc\r\nDataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\r\n100\t100\t2\t2\tmm\r\nFrame#\tTime\tA\t\t\tB\t\t\r\n\t\tX1\tY1\tZ1\tX2\tY2\tZ2\r\n\r\n1\t0.00\t1\t2\t3\t4\t5\t6\r\n2\t0.01\t7\t8\t9\r\n";

    #[test]
    fn reads_markers_and_gaps() {
        let p = read(SAMPLE.as_bytes(), &ReadLimits::default()).unwrap();
        let m = &p.motion;
        assert_eq!(m.point_names, vec!["A", "B"]);
        assert_eq!(m.frame_count(), 2);
        assert_eq!(m.fps, 100.0);
        assert_eq!(p.declared_unit, Some(0.001));
        assert_eq!(m.sample(1, 0), Some([7.0, 8.0, 9.0]));
        assert_eq!(m.sample(1, 1), None);
        assert!(p.warnings.is_empty());
    }

    #[test]
    fn short_files_fail_with_a_line() {
        for cut in [0, 20, 60, 90] {
            assert!(matches!(
                read(&SAMPLE.as_bytes()[..cut], &ReadLimits::default()),
                Err(Error::Parse { .. })
            ));
        }
        let bad = SAMPLE.replace("\t7\t", "\tseven\t");
        assert!(matches!(
            read(bad.as_bytes(), &ReadLimits::default()),
            Err(Error::Parse {
                at: Location::Line(8),
                ..
            })
        ));
    }
}
