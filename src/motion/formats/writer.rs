//! Point formats written block by block: a header, then frames as they come, then a tail.
//!
//! Why: a range answer of a long take must not be built whole in memory (16 JSON answers of
//! a 2.6 M-frame take held 1.2 GB). A writer knows the answer's shape up front (frame rate,
//! unit, point names, frame count) and then turns each block of whole frames into bytes, so
//! the server holds one block and its text at a time. [`super::write`] drives the same writer
//! over a whole take, so there is one implementation of each format, not a streaming copy.

use std::io::Write as _;

use crate::motion::units::Unit;

/// What a writer knows before the first frame.
#[derive(Debug, Clone)]
pub struct Shape {
    pub fps: f64,
    pub unit: Unit,
    /// Shared with the take's decoder, so that an answer of every point need not copy them.
    pub point_names: std::sync::Arc<[String]>,
    /// Frames the answer will hold: headers that state a count (TRC, NPY) state this one.
    pub frames: usize,
}

impl Shape {
    /// The shape of a whole take.
    pub fn of(m: &crate::motion::Motion) -> Shape {
        Shape {
            fps: m.fps,
            unit: m.unit.clone(),
            point_names: m.point_names.as_slice().into(),
            frames: m.frame_count(),
        }
    }

    /// Values (coordinates) per frame.
    pub fn width(&self) -> usize {
        self.point_names.len() * 3
    }
}

/// A format writer: [`FrameWriter::head`] once, [`FrameWriter::frames`] for consecutive
/// blocks of `n` whole frames (`n × points × 3` values, NaN for a missing sample; `n` is
/// given because a take may have frames and no points) that add up to [`Shape::frames`],
/// then [`FrameWriter::tail`] once.
pub trait FrameWriter: Send + Sync {
    fn head(&mut self, out: &mut Vec<u8>);
    fn frames(&mut self, n: usize, values: &[f32], out: &mut Vec<u8>);
    fn tail(&mut self, _out: &mut Vec<u8>) {}
    /// The whole output's length in bytes, where the format fixes it up front (binary
    /// formats): a server sends it as `Content-Length`.
    fn exact_len(&self) -> Option<u64> {
        None
    }
    /// The most bytes one frame takes (a server sizes its pieces of output by it).
    fn frame_bytes(&self) -> usize;
}

/// The most bytes a coordinate takes as text, and its separator. Values are printed with
/// Rust's `Display` (the shortest digits that parse back, never an exponent), so the
/// longest is the smallest subnormal, `-0.` and 45 digits: 48 characters.
pub(crate) const TEXT_VALUE_BYTES: usize = 49;

/// Append `v` in the shortest form that parses back to the same f32; NaN as `nan_text`.
pub(crate) fn push_f32(out: &mut Vec<u8>, v: f32, nan_text: &str) {
    if v.is_finite() {
        let _ = write!(out, "{v}");
    } else {
        out.extend_from_slice(nan_text.as_bytes());
    }
}

/// Everything a writer writes for `n` frames of `values` (all of [`Shape::frames`]) in one
/// buffer.
pub fn write_whole(mut w: Box<dyn FrameWriter>, n: usize, values: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(
        w.exact_len()
            .map_or(values.len() * 10 + 512, |n| n as usize),
    );
    w.head(&mut out);
    w.frames(n, values, &mut out);
    w.tail(&mut out);
    out
}
