//! CSV output for spreadsheets and pandas: one row per frame, `frame,time,` then
//! `<point>_x,<point>_y,<point>_z` per point; an empty cell is a missing sample.

use std::fmt::Write as _;

use super::text::push_f32;
use crate::motion::model::Motion;

/// Quote a header cell only when it needs it (RFC 4180).
fn cell(name: &str) -> String {
    if name.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", name.replace('"', "\"\""))
    } else {
        name.to_string()
    }
}

pub fn write(motion: &Motion) -> Vec<u8> {
    let mut out = String::with_capacity(motion.positions().len() * 10 + 256);
    out.push_str("frame,time");
    for n in &motion.point_names {
        for axis in ["x", "y", "z"] {
            out.push(',');
            out.push_str(&cell(&format!("{n}_{axis}")));
        }
    }
    out.push('\n');
    for f in 0..motion.frame_count() {
        let _ = write!(out, "{f},{}", f as f64 / motion.fps);
        for v in motion.frame(f) {
            out.push(',');
            push_f32(&mut out, *v, "");
        }
        out.push('\n');
    }
    out.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;
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
        let text = String::from_utf8(write(&m)).unwrap();
        assert_eq!(
            text,
            "frame,time,\"a,b_x\",\"a,b_y\",\"a,b_z\"\n0,0,1,2.5,3\n1,0.5,,,\n"
        );
    }
}
