//! Euler branches: which of a rotation's equivalent Euler triples a decoded joint shows.
//!
//! A rotation has two Euler triples in a given order, `(a, b, c)` and `(a + 180°, 180° − b,
//! c + 180°)`, each with any number of 360° turns per angle. Positions cannot tell them
//! apart; an animator's curve editor can, as a flip or a wrap. `rot` and `pga` code
//! rotations as quaternions and give back the triple nearest the previous frame, so a
//! chunk is continuous but starts on the canonical branch (middle angle in [−90°, 90°], each
//! angle in (−180°, 180°]) and does not follow the source where the source itself jumps.
//!
//! From `rot` version 3 and `pga` version 3, each chunk ends with its *branch changes*: per
//! joint with three Euler channels, the frames at which the source's triple is nearer
//! another branch of the decoded rotation than the branch in use, and which branch (a flip
//! bit and a number of turns per angle). The decoder applies each from its frame on. So
//! every decoded triple is the one nearest the source's, at the chunk's first frame and
//! wherever the source wraps, and between changes it stays continuous. A chunk whose
//! triples already follow the source costs one bit.

use super::entropy::ints::IntModel;
use super::entropy::io::Io;
use super::entropy::rangecoder::Bit;
use super::error::{malformed, Result};
use super::skeleton::{printed, Skeleton};
use crate::motion::rotation::euler_order;

/// A joint whose rotation is three Euler channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Turning {
    /// Its channels' indices in a frame, in channel order.
    pub idx: [usize; 3],
    /// Their axes (0 = x), in channel order.
    pub order: [usize; 3],
}

/// Every joint of `rig` with three rotation channels about three axes, in rig order.
pub fn turnings(rig: &Skeleton) -> Vec<Turning> {
    let mut out = Vec::new();
    let mut first = 0;
    for joint in rig.joints() {
        if let Some(order) = euler_order(&joint.channels) {
            let mut idx = [0; 3];
            let rot = joint
                .channels
                .iter()
                .enumerate()
                .filter(|(_, c)| c.rotation_axis().is_some())
                .map(|(c, _)| first + c);
            for (slot, i) in idx.iter_mut().zip(rot) {
                *slot = i;
            }
            out.push(Turning { idx, order });
        }
        first += joint.channels.len();
    }
    out
}

/// One branch of a triple: flipped or not, then turned by whole turns per angle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Branch {
    flip: bool,
    turns: [i32; 3],
}

/// Turns past this are not motion (a source angle of 10⁹ degrees); the encoder clamps and
/// the decoder refuses them, so no decoded angle overflows what a file prints.
const MAX_TURNS: i32 = 1 << 20;

impl Branch {
    fn apply(self, e: [f64; 3]) -> [f64; 3] {
        let mut e = if self.flip {
            [e[0] + 180.0, 180.0 - e[1], e[2] + 180.0]
        } else {
            e
        };
        for (v, t) in e.iter_mut().zip(self.turns) {
            *v += 360.0 * f64::from(t);
        }
        e
    }

    /// The branch of `e` nearest `target` (the sum of absolute angle differences).
    fn nearest(e: [f64; 3], target: [f64; 3]) -> Branch {
        let mut best = (f64::INFINITY, Branch::default());
        for flip in [false, true] {
            let y = Branch {
                flip,
                turns: [0; 3],
            }
            .apply(e);
            let mut turns = [0; 3];
            for k in 0..3 {
                let t = ((target[k] - y[k]) / 360.0).round();
                turns[k] = t.clamp(-f64::from(MAX_TURNS), f64::from(MAX_TURNS)) as i32;
            }
            let b = Branch { flip, turns };
            let d = distance(b.apply(e), target);
            if d < best.0 {
                best = (d, b);
            }
        }
        best.1
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum()
}

fn triple(frame: &[f64], t: &Turning) -> [f64; 3] {
    t.idx.map(|i| frame[i])
}

/// A change of branch must bring the triple this much nearer the source (degrees, summed
/// over the three angles): ties and rounding never cost bits.
const GAIN: f64 = 1e-3;

/// Each turning's branch changes: where `source`'s triples leave the branch in use of
/// `decoded`'s.
fn changes(
    turnings: &[Turning],
    channels: usize,
    source: &[f64],
    decoded: &[f64],
) -> Vec<Vec<(usize, Branch)>> {
    turnings
        .iter()
        .map(|t| {
            let mut current = Branch::default();
            let mut out = Vec::new();
            for (f, (s, d)) in source
                .chunks_exact(channels)
                .zip(decoded.chunks_exact(channels))
                .enumerate()
            {
                let (s, d) = (triple(s, t), triple(d, t));
                if !s.iter().chain(&d).all(|v| v.is_finite()) {
                    continue;
                }
                let best = Branch::nearest(d, s);
                if best != current
                    && distance(best.apply(d), s) + GAIN < distance(current.apply(d), s)
                {
                    out.push((f, best));
                    current = best;
                }
            }
            out
        })
        .collect()
}

/// A chunk's branch changes through `io` (from `source`, its channel values, when
/// encoding), applied to `decoded` (`frames × channels`, the codec's continuous triples, as
/// printed). Trial runs that only measure positions ([`Io::dry`]) skip it: a branch never
/// moves a position.
pub fn code<I: Io>(
    io: &mut I,
    turnings: &[Turning],
    channels: usize,
    source: Option<&[f64]>,
    decoded: &mut [f64],
) -> Result<()> {
    if io.dry() || channels == 0 {
        return Ok(());
    }
    let frames = decoded.len() / channels;
    let given = match source {
        Some(s) if io.encoding() => changes(turnings, channels, s, decoded),
        _ => vec![Vec::new(); turnings.len()],
    };
    let mut any = Bit::default();
    if !io.bit(&mut any, given.iter().any(|c| !c.is_empty())) {
        return Ok(());
    }
    let (mut count, mut gap, mut turn) = (
        IntModel::default(),
        IntModel::default(),
        IntModel::default(),
    );
    let mut flip = Bit::default();
    for (t, given) in turnings.iter().zip(&given) {
        let n = io.int(&mut count, given.len() as i32);
        if n < 0 || n as usize > frames {
            return Err(malformed(format!(
                "{n} branch changes in a chunk of {frames} frames"
            )));
        }
        let mut at = 0usize;
        let mut current = Branch::default();
        let mut start = 0usize;
        for e in 0..n as usize {
            let (gf, gb) = given.get(e).copied().unwrap_or_default();
            let g = io.int(&mut gap, gf.saturating_sub(at) as i32);
            let f = usize::try_from(g)
                .ok()
                .and_then(|g| at.checked_add(g))
                .filter(|&f| f < frames)
                .ok_or_else(|| malformed("a branch change past the chunk"))?;
            let mut b = Branch {
                flip: io.bit(&mut flip, gb.flip),
                turns: [0; 3],
            };
            for k in 0..3 {
                b.turns[k] = io.int(&mut turn, gb.turns[k]);
                if b.turns[k].abs() > MAX_TURNS {
                    return Err(malformed(format!("a branch of {} turns", b.turns[k])));
                }
            }
            apply(decoded, channels, t, current, start..f);
            (current, start, at) = (b, f, f + 1);
        }
        apply(decoded, channels, t, current, start..frames);
    }
    Ok(())
}

fn apply(
    decoded: &mut [f64],
    channels: usize,
    t: &Turning,
    b: Branch,
    frames: std::ops::Range<usize>,
) {
    if b == Branch::default() {
        return;
    }
    for f in frames {
        let row = &mut decoded[f * channels..(f + 1) * channels];
        let e = b.apply(triple(row, t));
        for (k, i) in t.idx.iter().enumerate() {
            row[*i] = printed(e[k]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::entropy::io::Dry;
    use crate::codec::entropy::rangecoder::{Decoder, Encoder};
    use crate::motion::rotation::{from_euler, to_euler};

    const ORDER: [usize; 3] = [2, 0, 1];

    /// Frames of one joint (three channels after three position channels): the source
    /// wraps at 180° on its first angle and starts on the other branch with a turn.
    fn frames() -> (Vec<f64>, Vec<f64>) {
        let mut source = Vec::new();
        let mut decoded = Vec::new();
        let mut near = None;
        for f in 0..40 {
            let a = 150.0 + 3.0 * f as f64; // passes 180° at frame 10
            let s = if a > 180.0 { a - 360.0 } else { a };
            // The source's first ten frames on the other branch, one turn up.
            let src = if f < 10 {
                [s + 180.0, 180.0 - 20.0, 10.0 + 180.0 + 360.0]
            } else {
                [s, 20.0, 10.0]
            };
            let q = from_euler(ORDER, src);
            let e = to_euler(&q, ORDER, near);
            near = Some(e);
            source.extend([1.0, 2.0, 3.0]);
            source.extend(src);
            decoded.extend([1.0, 2.0, 3.0]);
            decoded.extend(e.map(printed));
        }
        (source, decoded)
    }

    #[test]
    fn decoded_triples_come_back_nearest_the_sources_and_continuous_between_changes() {
        let t = [Turning {
            idx: [3, 4, 5],
            order: ORDER,
        }];
        let (source, decoded) = frames();
        let far = |d: &[f64]| {
            d.chunks_exact(6)
                .zip(source.chunks_exact(6))
                .map(|(d, s)| distance(triple(d, &t[0]), triple(s, &t[0])))
                .fold(0.0, f64::max)
        };
        assert!(
            far(&decoded) > 90.0,
            "the test starts off the source's branch"
        );
        let mut enc_out = decoded.clone();
        let mut enc = Encoder::new();
        code(&mut enc, &t, 6, Some(&source), &mut enc_out).unwrap();
        let bytes = enc.finish();
        assert!(far(&enc_out) < 1e-4, "{}", far(&enc_out));
        let mut dec_out = decoded.clone();
        code(&mut Decoder::new(&bytes), &t, 6, None, &mut dec_out).unwrap();
        assert_eq!(dec_out, enc_out);
        // Positions are untouched; a dry run changes nothing.
        assert!(dec_out.chunks_exact(6).all(|r| r[..3] == [1.0, 2.0, 3.0]));
        let mut dry = decoded.clone();
        code(&mut Dry, &t, 6, Some(&source), &mut dry).unwrap();
        assert_eq!(dry, decoded);
    }

    #[test]
    fn a_chunk_already_on_the_sources_branches_costs_one_bit() {
        let t = [Turning {
            idx: [3, 4, 5],
            order: ORDER,
        }];
        let (_, decoded) = frames();
        let mut out = decoded.clone();
        let mut enc = Encoder::new();
        code(&mut enc, &t, 6, Some(&decoded), &mut out).unwrap();
        let mut one = Encoder::new();
        one.encode(&mut Bit::default(), false);
        assert_eq!(enc.finish(), one.finish());
        assert_eq!(out, decoded);
    }

    #[test]
    fn damaged_changes_are_refused_or_harmless() {
        let t = [
            Turning {
                idx: [3, 4, 5],
                order: ORDER,
            },
            Turning {
                idx: [0, 1, 2],
                order: ORDER,
            },
        ];
        let (_, decoded) = frames();
        for seed in 0..200u32 {
            let bytes: Vec<u8> = (0..12)
                .map(|i| (seed.wrapping_mul(2654435761).rotate_left(i) >> 3) as u8)
                .collect();
            let mut out = decoded.clone();
            if code(&mut Decoder::new(&bytes), &t, 6, None, &mut out).is_ok() {
                assert!(out.iter().all(|v| v.is_finite()));
            }
        }
    }
}
