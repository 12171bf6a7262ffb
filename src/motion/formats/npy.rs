//! NumPy `.npy` arrays of shape `[frames, points, 3]`, float32 or float64, either byte order,
//! C or Fortran order. NaN marks a missing sample. NPY carries no frame rate, names or unit:
//! the frame rate is [`DEFAULT_FPS`] unless the caller states one (with a warning from
//! [`super::read_as`]), points are named `P1…`, and the unit is inferred.

use super::writer::{FrameWriter, Shape};
use super::{perr, unsettled_unit, Format, Parsed, ReadLimits};
use crate::motion::error::{Error, Location, Result};
use crate::motion::model::Motion;

const MAGIC: &[u8] = b"\x93NUMPY";

fn err(offset: usize, reason: impl Into<String>) -> Error {
    perr(Format::Npy, Location::Offset(offset), reason)
}

/// Frame rate given to arrays, which have none; a warning says so.
pub const DEFAULT_FPS: f64 = 1.0;

struct Header {
    little_endian: bool,
    item: usize,
    fortran: bool,
    shape: Vec<usize>,
}

fn parse_header(h: &str, at: usize) -> Result<Header> {
    let value_of = |key: &str| -> Result<&str> {
        let k = h
            .find(&format!("'{key}'"))
            .or_else(|| h.find(&format!("\"{key}\"")))
            .ok_or_else(|| err(at, format!("header has no '{key}'")))?;
        let rest = &h[k + key.len() + 2..];
        let colon = rest
            .find(':')
            .ok_or_else(|| err(at, format!("'{key}' has no value")))?;
        Ok(rest[colon + 1..].trim_start())
    };
    let descr = value_of("descr")?;
    let descr = descr
        .get(1..)
        .and_then(|d| d.split(['\'', '"']).next())
        .ok_or_else(|| err(at, "unreadable descr"))?;
    let (little_endian, item) = match descr {
        "<f4" | "=f4" => (true, 4),
        "<f8" | "=f8" => (true, 8),
        ">f4" => (false, 4),
        ">f8" => (false, 8),
        other => {
            return Err(err(
                at,
                format!("dtype {other:?} unsupported: use float32 or float64"),
            ))
        }
    };
    let fortran = value_of("fortran_order")?.starts_with("True");
    let shape_text = value_of("shape")?;
    let close = shape_text
        .find(')')
        .ok_or_else(|| err(at, "unterminated shape"))?;
    let inner = shape_text
        .get(1..close)
        .filter(|_| shape_text.starts_with('('))
        .ok_or_else(|| err(at, "shape is not a tuple"))?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| err(at, format!("shape entry {s:?} is not a number")))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Header {
        little_endian,
        item,
        fortran,
        shape,
    })
}

pub(crate) fn read(bytes: &[u8], limits: &ReadLimits) -> Result<Parsed> {
    if !bytes.starts_with(MAGIC) || bytes.len() < 10 {
        return Err(err(0, "missing the \\x93NUMPY magic"));
    }
    let major = bytes[6];
    let (len, start): (usize, usize) = match major {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(err(6, format!("NPY version {v} unsupported"))),
    };
    let data_at = start
        .checked_add(len)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| err(8, "header runs past the end of the file"))?;
    let h = parse_header(&String::from_utf8_lossy(&bytes[start..data_at]), start)?;
    let [frames, points, three] = h.shape[..] else {
        return Err(err(
            start,
            format!("shape {:?} is not [frames, points, 3]", h.shape),
        ));
    };
    if three != 3 {
        return Err(err(
            start,
            format!("last axis has {three} entries, expected 3 (x, y, z)"),
        ));
    }
    limits.check_shape(frames, points)?;
    let count = frames * points * 3;
    let need = count * h.item;
    if bytes.len() - data_at < need {
        return Err(err(
            data_at,
            format!(
                "data holds {} bytes, shape needs {need}",
                bytes.len() - data_at
            ),
        ));
    }
    let data = &bytes[data_at..data_at + need];
    let value = |i: usize| -> f32 {
        let b = &data[i * h.item..(i + 1) * h.item];
        match (h.item, h.little_endian) {
            (4, true) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            (4, false) => f32::from_be_bytes([b[0], b[1], b[2], b[3]]),
            (_, true) => f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32,
            (_, false) => f64::from_be_bytes(b.try_into().expect("8 bytes")) as f32,
        }
    };
    let mut positions = vec![0.0f32; count];
    for f in 0..frames {
        for p in 0..points {
            for k in 0..3 {
                let src = if h.fortran {
                    f + frames * (p + points * k)
                } else {
                    (f * points + p) * 3 + k
                };
                positions[(f * points + p) * 3 + k] = value(src);
            }
        }
    }
    let names = (1..=points).map(|i| format!("P{i}")).collect();
    // NaN is how an array marks a gap; ±infinity is no position either.
    let warnings = super::non_finite_warning(super::infinite_samples(&positions))
        .into_iter()
        .collect();
    let motion = if points == 0 {
        Motion::without_points(DEFAULT_FPS, unsettled_unit(), frames)?
    } else {
        Motion::new(DEFAULT_FPS, unsettled_unit(), names, positions, None)?
    };
    Ok(Parsed {
        motion,
        declared_unit: None,
        warnings,
        contradictions: Vec::new(),
        extras: Default::default(),
    })
}

/// NPY: its header (with the shape), then the values as they come.
pub struct Writer {
    shape: Shape,
    header: Vec<u8>,
}

impl Writer {
    pub fn new(shape: Shape) -> Writer {
        let dict = format!(
            "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, 3), }}",
            shape.frames,
            shape.point_names.len()
        );
        // Pad so that the data starts on a 64-byte boundary, as NumPy does.
        let unpadded = MAGIC.len() + 4 + dict.len() + 1;
        let pad = (64 - unpadded % 64) % 64;
        let header_len = dict.len() + pad + 1;
        let mut header = Vec::with_capacity(unpadded + pad);
        header.extend_from_slice(MAGIC);
        header.extend_from_slice(&[1, 0]);
        header.extend_from_slice(&(header_len as u16).to_le_bytes());
        header.extend_from_slice(dict.as_bytes());
        header.extend(std::iter::repeat_n(b' ', pad));
        header.push(b'\n');
        Writer { shape, header }
    }
}

impl FrameWriter for Writer {
    fn head(&mut self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.header);
    }

    fn frames(&mut self, _n: usize, values: &[f32], out: &mut Vec<u8>) {
        super::rawf32::extend_le(out, values);
    }

    fn exact_len(&self) -> Option<u64> {
        Some(self.header.len() as u64 + (self.shape.frames * self.shape.width() * 4) as u64)
    }

    fn frame_bytes(&self) -> usize {
        self.shape.width() * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(descr: &str, fortran: bool, shape: &str, data: &[u8]) -> Vec<u8> {
        let dict = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}\n",
            if fortran { "True" } else { "False" }
        );
        let mut b = MAGIC.to_vec();
        b.extend_from_slice(&[1, 0]);
        b.extend_from_slice(&(dict.len() as u16).to_le_bytes());
        b.extend_from_slice(dict.as_bytes());
        b.extend_from_slice(data);
        b
    }

    #[test]
    fn reads_f8_big_endian_and_fortran_order() {
        let vals: Vec<f64> = (0..6).map(f64::from).collect();
        let be: Vec<u8> = vals.iter().flat_map(|v| v.to_be_bytes()).collect();
        let m = read(&npy(">f8", false, "(2, 1, 3)", &be), &ReadLimits::default())
            .unwrap()
            .motion;
        assert_eq!(m.positions(), &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        // Fortran order: element (f, p, k) at f + F*(p + P*k); 2 frames × 1 point.
        let le: Vec<u8> = vals
            .iter()
            .flat_map(|v| (*v as f32).to_le_bytes())
            .collect();
        let m = read(&npy("<f4", true, "(2, 1, 3)", &le), &ReadLimits::default())
            .unwrap()
            .motion;
        assert_eq!(m.positions(), &[0.0, 2.0, 4.0, 1.0, 3.0, 5.0]);
    }

    #[test]
    fn rejects_bad_shapes_and_short_data() {
        let d = vec![0u8; 24];
        assert!(read(&npy("<f4", false, "(2, 3)", &d), &ReadLimits::default()).is_err());
        assert!(read(&npy("<f4", false, "(2, 1, 4)", &d), &ReadLimits::default()).is_err());
        assert!(read(&npy("<f4", false, "(3, 1, 3)", &d), &ReadLimits::default()).is_err());
        assert!(read(&npy("<i4", false, "(2, 1, 3)", &d), &ReadLimits::default()).is_err());
    }

    #[test]
    fn writes_aligned_data() {
        let m = read(
            &npy("<f4", false, "(2, 1, 3)", &[0u8; 24]),
            &ReadLimits::default(),
        )
        .unwrap()
        .motion;
        let out = super::super::write(&m, super::super::Format::Npy).unwrap();
        assert_eq!((out.len() - 24) % 64, 0);
        assert_eq!(read(&out, &ReadLimits::default()).unwrap().motion, m);
    }
}
