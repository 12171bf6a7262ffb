//! A take's motion features as stored ([`crate::motion::features`]: one descriptor of
//! [`DIMS`] numbers per 1 s window), about 30 bytes a window.
//!
//! # Values
//! Each number is kept as one signed byte on a logarithmic scale ([`to_code`]): fine near
//! zero, where most places and spreads lie, and still able to hold a dash's pelvis speed
//! (40 in the descriptor's units) at 3 % of itself. Search compares descriptors by
//! Euclidean distance, and the step between codes (0.003 near 0, 0.03 at 1) lies well
//! under the distances that tell motions apart (`mocapstore bench --search` gives the same
//! precision from stored descriptors as from exact ones).
//!
//! # Layout (little-endian)
//! `version u8` (1), `dims u8`, `window u8`, `hop u8` (frames at [`RATE`]: what the
//! descriptors were taken with; a reader of other numbers refuses them), `frames u32` (the
//! take's frames at [`RATE`], so that each window's range is known: window `i` spans
//! `[i × hop, min(i × hop + window, frames))`), `windows u32`, `placed u16` (bit `i`: key
//! role `i` of [`KEY_ROLES`] is placed; bit 15: the pelvis), `leg_mm u16` (the leg length
//! the take was scaled by, 0 when its height stood in), `zstd length u32` and the zstd frame
//! of `windows × dims` bytes, dimension after dimension, each dimension's codes as
//! differences from the window before (consecutive windows overlap by half, so those are
//! small), then `crc32c u32` of every byte before it.

use super::error::{malformed, Error, Result};
use crate::motion::body::Role;
use crate::motion::features::{Features, DIMS, HOP, KEY_ROLES, RATE, WINDOW};

const VERSION: u8 = 1;
/// Bit of `placed` that says the pelvis is.
const PELVIS_BIT: u16 = 1 << 15;
const ZSTD_LEVEL: i32 = 19;
const HEADER: usize = 1 + 3 + 4 + 4 + 2 + 2 + 4;

/// The logarithmic scale: a code of `c` is `sign · A · ((1 + TOP / A)^(|c| / 127) − 1)`.
const A: f64 = 0.05;
const TOP: f64 = 64.0;

/// One descriptor.
pub type Descriptor = [f32; DIMS];

/// A take's stored features.
#[derive(Debug, Clone, PartialEq)]
pub struct Stored {
    /// The take's frames at [`RATE`].
    pub frames: u32,
    /// One per window, window `i` starting at frame `i × HOP`.
    pub windows: Vec<Descriptor>,
    /// The key roles placed, in [`KEY_ROLES`] order, and whether the pelvis is.
    pub placed: Vec<Role>,
    pub pelvis: bool,
    /// The leg length the take was scaled by, in metres, if its legs are placed.
    pub leg_m: Option<f32>,
}

impl Stored {
    /// Window `i`'s frames at [`RATE`]: `[start, end)`.
    pub fn span(&self, i: usize) -> (usize, usize) {
        let start = i * HOP;
        (
            start,
            (start + WINDOW).min(self.frames as usize).max(start + 1),
        )
    }

    /// Seconds from frames at [`RATE`].
    pub fn seconds(frames: usize) -> f64 {
        frames as f64 / RATE
    }

    /// Bytes held in memory.
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.windows.len() * DIMS * 4 + self.placed.len()
    }
}

fn log_span() -> f64 {
    (1.0 + TOP / A).ln()
}

/// A descriptor's number as a code.
pub fn to_code(v: f32) -> i8 {
    if !v.is_finite() {
        return 0;
    }
    let m = (f64::from(v.abs()) / A).ln_1p() / log_span() * 127.0;
    let c = m.round().min(127.0) as i8;
    if v < 0.0 {
        -c
    } else {
        c
    }
}

/// A code's number.
pub fn from_code(c: i8) -> f32 {
    let m = f64::from(c.unsigned_abs()) / 127.0;
    let v = A * (m * log_span()).exp_m1();
    (if c < 0 { -v } else { v }) as f32
}

/// `f`, of a take of `frames` frames at [`RATE`], as stored bytes.
pub fn encode(f: &Features, pelvis: bool, frames: usize) -> Result<Vec<u8>> {
    let windows = f.windows.len();
    let frames = u32::try_from(frames)
        .map_err(|_| Error::Invalid(format!("{frames} frames of features")))?;
    let mut codes = vec![0u8; windows * DIMS];
    for d in 0..DIMS {
        let mut before = 0i8;
        for (i, w) in f.windows.iter().enumerate() {
            let c = to_code(w.descriptor[d]);
            codes[d * windows + i] = c.wrapping_sub(before) as u8;
            before = c;
        }
    }
    let packed = zstd::bulk::compress(&codes, ZSTD_LEVEL)
        .map_err(|e| Error::Fault(format!("zstd of features: {e}")))?;
    let mut placed = if pelvis { PELVIS_BIT } else { 0 };
    for (i, r) in KEY_ROLES.iter().enumerate() {
        if f.placed.contains(r) {
            placed |= 1 << i;
        }
    }
    let leg_mm = f
        .leg_m
        .map_or(0, |l| (l * 1000.0).round().clamp(1.0, 65535.0) as u16);
    let mut out = Vec::with_capacity(HEADER + packed.len() + 4);
    out.extend_from_slice(&[VERSION, DIMS as u8, WINDOW as u8, HOP as u8]);
    out.extend_from_slice(&frames.to_le_bytes());
    out.extend_from_slice(&(windows as u32).to_le_bytes());
    out.extend_from_slice(&placed.to_le_bytes());
    out.extend_from_slice(&leg_mm.to_le_bytes());
    out.extend_from_slice(&(packed.len() as u32).to_le_bytes());
    out.extend_from_slice(&packed);
    let crc = crc32c::crc32c(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    Ok(out)
}

/// Stored bytes back as the features they hold; at most `max_windows` windows are
/// accepted before anything is allocated.
pub fn decode(bytes: &[u8], max_windows: u64) -> Result<Stored> {
    let bad = |what: &str| malformed(format!("motion features: {what}"));
    if bytes.len() < HEADER + 4 {
        return Err(bad("cut short"));
    }
    let (body, crc) = bytes.split_at(bytes.len() - 4);
    if crc32c::crc32c(body) != u32::from_le_bytes(crc.try_into().expect("4 bytes")) {
        return Err(Error::Checksum("motion features".into()));
    }
    if body[0] != VERSION {
        return Err(Error::Unsupported(format!(
            "motion features version {}",
            body[0]
        )));
    }
    if (body[1] as usize, body[2] as usize, body[3] as usize) != (DIMS, WINDOW, HOP) {
        return Err(Error::Unsupported(format!(
            "motion features of {} numbers, windows of {} frames every {}: this server takes \
             {DIMS}, {WINDOW} and {HOP}",
            body[1], body[2], body[3]
        )));
    }
    let u32_at = |at: usize| u32::from_le_bytes(body[at..at + 4].try_into().expect("4 bytes"));
    let u16_at = |at: usize| u16::from_le_bytes(body[at..at + 2].try_into().expect("2 bytes"));
    let frames = u32_at(4);
    let windows = u32_at(8);
    let (placed, leg_mm) = (u16_at(12), u16_at(14));
    let packed_len = u32_at(16) as usize;
    if u64::from(windows) > max_windows {
        return Err(Error::Limit {
            what: "windows of motion features",
            actual: windows.into(),
            limit: max_windows,
        });
    }
    let windows = windows as usize;
    if windows > 0 && (windows - 1) * HOP >= frames.max(1) as usize {
        return Err(bad("more windows than its frames have"));
    }
    let packed = body.get(HEADER..).filter(|p| p.len() == packed_len);
    let packed = packed.ok_or_else(|| bad("length of its values"))?;
    let codes =
        zstd::bulk::decompress(packed, windows * DIMS).map_err(|e| bad(&format!("values: {e}")))?;
    if codes.len() != windows * DIMS {
        return Err(bad("values of another count"));
    }
    let table: Vec<f32> = (0..=255u8).map(|b| from_code(b as i8)).collect();
    let mut out = vec![[0f32; DIMS]; windows];
    for d in 0..DIMS {
        let mut code = 0i8;
        for (i, w) in out.iter_mut().enumerate() {
            code = code.wrapping_add(codes[d * windows + i] as i8);
            w[d] = table[code as u8 as usize];
        }
    }
    Ok(Stored {
        frames,
        windows: out,
        placed: KEY_ROLES
            .iter()
            .enumerate()
            .filter(|(i, _)| placed & (1 << i) != 0)
            .map(|(_, r)| *r)
            .collect(),
        pelvis: placed & PELVIS_BIT != 0,
        leg_m: (leg_mm > 0).then(|| f32::from(leg_mm) / 1000.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::features::Window;

    fn sample(windows: usize) -> Features {
        Features {
            windows: (0..windows)
                .map(|i| Window {
                    start: i * HOP,
                    descriptor: std::array::from_fn(|d| {
                        ((i as f32 * 0.3 + d as f32).sin()) * (d % 7) as f32 * 3.0
                    }),
                })
                .collect(),
            placed: KEY_ROLES[..5].to_vec(),
            leg_m: Some(0.912),
        }
    }

    #[test]
    fn codes_keep_numbers_within_a_few_percent_and_order() {
        for v in [0.0f32, 0.001, -0.02, 0.3, -1.0, 2.5, 7.0, -39.0, 64.0] {
            let back = from_code(to_code(v));
            assert!(
                (back - v).abs() <= 0.002 + 0.03 * v.abs(),
                "{v} came back {back}"
            );
        }
        // Past the top, the top; the scale is monotone.
        assert_eq!(to_code(1e6), 127);
        assert_eq!(to_code(-1e6), -127);
        assert!((-127..127).all(|c| from_code(c) < from_code(c + 1)));
    }

    #[test]
    fn features_round_trip_to_their_codes() {
        let f = sample(40);
        let bytes = encode(&f, true, 40 * HOP + 15).unwrap();
        let s = decode(&bytes, 1000).unwrap();
        assert_eq!(s.frames as usize, 40 * HOP + 15);
        assert_eq!(s.windows.len(), 40);
        assert_eq!(s.placed, KEY_ROLES[..5].to_vec());
        assert!(s.pelvis);
        assert_eq!(s.leg_m, Some(0.912));
        for (w, back) in f.windows.iter().zip(&s.windows) {
            for (b, v) in back.iter().zip(&w.descriptor) {
                assert_eq!(*b, from_code(to_code(*v)));
            }
        }
        assert_eq!(s.span(39), (39 * HOP, 39 * HOP + WINDOW));
        // Smaller than a byte a number: the windows overlap, so their codes repeat.
        assert!(bytes.len() < 40 * DIMS, "{} bytes", bytes.len());
    }

    #[test]
    fn damaged_or_foreign_bytes_are_refused_not_read() {
        let bytes = encode(&sample(3), false, 60).unwrap();
        let mut flipped = bytes.clone();
        flipped[HEADER + 1] ^= 1;
        assert!(matches!(decode(&flipped, 100), Err(Error::Checksum(_))));
        assert!(decode(&bytes[..10], 100).is_err());
        assert!(matches!(decode(&bytes, 2), Err(Error::Limit { .. })));
        // A window count the frames cannot hold, with a valid checksum.
        let mut lying = bytes[..bytes.len() - 4].to_vec();
        lying[4..8].copy_from_slice(&1u32.to_le_bytes());
        let crc = crc32c::crc32c(&lying);
        lying.extend_from_slice(&crc.to_le_bytes());
        assert!(matches!(decode(&lying, 100), Err(Error::Malformed(_))));
        let empty = encode(&sample(0), false, 0).unwrap();
        assert!(decode(&empty, 100).unwrap().windows.is_empty());
    }
}
