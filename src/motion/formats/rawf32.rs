//! Bare little-endian f32, `frames × points × 3`, NaN for missing samples: the cheapest
//! thing to hand to NumPy (`np.fromfile(..., '<f4').reshape(F, P, 3)`) or a GPU. It has no
//! header, so the shape travels out of band (the HTTP layer puts it in response headers).

use crate::motion::model::Motion;

pub fn write(motion: &Motion) -> Vec<u8> {
    motion
        .positions()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
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
        let b = write(&m);
        assert_eq!(b.len(), 12);
        assert_eq!(f32::from_le_bytes([b[4], b[5], b[6], b[7]]), -2.0);
    }
}
