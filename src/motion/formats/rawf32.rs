//! Bare little-endian f32, `frames × points × 3`, NaN for missing samples: the cheapest
//! thing to hand to NumPy (`np.fromfile(..., '<f4').reshape(F, P, 3)`) or a GPU. It has no
//! header, so the shape travels out of band (the HTTP layer puts it in response headers).

use super::writer::{FrameWriter, Shape};

/// Append `values` as little-endian f32.
pub(crate) fn extend_le(out: &mut Vec<u8>, values: &[f32]) {
    // Grown once and filled in place: a loop of 4-byte appends checks capacity at each one
    // and was the writer's whole cost in a profile of range reads; this compiles to
    // straight copies.
    let start = out.len();
    out.resize(start + values.len() * 4, 0);
    for (d, v) in out[start..].chunks_exact_mut(4).zip(values) {
        d.copy_from_slice(&v.to_le_bytes());
    }
}

/// Bare f32, block by block.
pub struct Writer {
    shape: Shape,
}

impl Writer {
    pub fn new(shape: Shape) -> Writer {
        Writer { shape }
    }
}

impl FrameWriter for Writer {
    fn head(&mut self, _out: &mut Vec<u8>) {}

    fn frames(&mut self, _n: usize, values: &[f32], out: &mut Vec<u8>) {
        extend_le(out, values);
    }

    fn exact_len(&self) -> Option<u64> {
        Some((self.shape.frames * self.shape.width() * 4) as u64)
    }

    fn frame_bytes(&self) -> usize {
        self.shape.width() * 4
    }
}

#[cfg(test)]
mod tests {
    use crate::motion::model::Motion;
    use crate::motion::units::Unit;

    #[test]
    fn little_endian_floats_in_frame_order() {
        let m = Motion::new(
            1.0,
            Unit::millimetres(),
            vec!["a".into()],
            vec![1.0, -2.0, 0.5],
            None,
        )
        .unwrap();
        let b = super::super::write(&m, super::super::Format::F32).unwrap();
        assert_eq!(b.len(), 12);
        assert_eq!(f32::from_le_bytes([b[4], b[5], b[6], b[7]]), -2.0);
    }
}
