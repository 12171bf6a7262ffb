//! CSV output for spreadsheets and pandas: one row per frame, `frame,time,` then
//! `<point>_x,<point>_y,<point>_z` per point; an empty cell is a missing sample.

use std::io::Write as _;

use super::writer::{push_f32, FrameWriter, Shape, TEXT_VALUE_BYTES};

/// Quote a header cell only when it needs it (RFC 4180).
fn cell(name: &str) -> String {
    if name.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", name.replace('"', "\"\""))
    } else {
        name.to_string()
    }
}

/// CSV row by row.
pub struct Writer {
    shape: Shape,
    written: usize,
}

impl Writer {
    pub fn new(shape: Shape) -> Writer {
        Writer { shape, written: 0 }
    }
}

impl FrameWriter for Writer {
    fn head(&mut self, out: &mut Vec<u8>) {
        out.extend_from_slice(b"frame,time");
        for n in self.shape.point_names.iter() {
            for axis in ["x", "y", "z"] {
                out.push(b',');
                out.extend_from_slice(cell(&format!("{n}_{axis}")).as_bytes());
            }
        }
        out.push(b'\n');
    }

    fn frames(&mut self, n: usize, values: &[f32], out: &mut Vec<u8>) {
        let w = self.shape.width();
        for f in 0..n {
            let at = self.written;
            self.written += 1;
            let _ = write!(out, "{at},{}", at as f64 / self.shape.fps);
            for v in &values[f * w..(f + 1) * w] {
                out.push(b',');
                push_f32(out, *v, "");
            }
            out.push(b'\n');
        }
    }

    fn frame_bytes(&self) -> usize {
        // The frame number and its time, then each value.
        48 + self.shape.width() * TEXT_VALUE_BYTES
    }
}

#[cfg(test)]
mod tests {
    use crate::motion::model::Motion;
    use crate::motion::units::Unit;

    #[test]
    fn writes_header_rows_and_gaps() {
        let m = Motion::new(
            2.0,
            Unit::millimetres(),
            vec!["a,b".into()],
            vec![1.0, 2.5, 3.0, f32::NAN, 0.0, 0.0],
            None,
        )
        .unwrap();
        let text =
            String::from_utf8(super::super::write(&m, super::super::Format::Csv).unwrap()).unwrap();
        assert_eq!(
            text,
            "frame,time,\"a,b_x\",\"a,b_y\",\"a,b_z\"\n0,0,1,2.5,3\n1,0.5,,,\n"
        );
    }
}
