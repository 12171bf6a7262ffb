//! Twists near gimbal lock: decoded Euler angles on the file's where the middle angle is
//! near ±90°.
//!
//! Near lock only `a + σc` of a triple `(a, b, c)` is well conditioned ([`sigma`]): a
//! rotation a fraction of a degree from the source's, as any bound on positions allows, can
//! decode with `a` and `c` tens of degrees from the file's, and its curves jump where the
//! file's do not (Bandai's walkers, 2 to 10 jumps over 90° per file). A *twist* `t` (whole
//! degrees) moves a decoded triple along the direction in which the rotation barely moves,
//! `(a + t, b, c − σt)`, to put `a` (and with it `c`) back on the file's.
//!
//! From `rot` version 4 and `pga` version 4 each joint with three Euler channels carries
//! its twist, coded frame by frame where the codec decodes the joint (`rot`: before its
//! children are aimed from it, so they are aimed from the rotation that decodes), only on
//! frames near lock: one adaptive bit per such frame says whether the twist changes, and
//! the new twist follows. Away from lock the twist is 0 and costs nothing. The encoder
//! takes a twist only where the triple is more than [`FAR`] from the file's, the twist
//! brings it nearer by more than [`SLACK`], and it leaves the rotation no farther from the
//! file's rotation, and keeps it while it stays within the slack; where the file's own
//! curve turns by nearly a jump it holds the triple to within [`TIGHT`] instead; and trial encodes run the same code, so the bound is judged on what
//! decodes; a chunk that cannot meet the bound with twists is coded without (one raw bit
//! per chunk). (Judged against `rot`'s aimed rotation instead, twists were seldom taken and
//! the jumps stayed; coded after the chunk, they moved aimed children and cost `rot` 12 %.)
//! Flips and whole turns are the [`branches`](super::branches)' job, after this.

use super::branches::Turning;
use super::entropy::ints::IntModel;
use super::entropy::io::Io;
use super::entropy::rangecoder::Bit;
use super::error::{malformed, Result};
use super::skeleton::printed;
use crate::motion::rotation::from_euler;

/// A twist is within a half turn either way; the decoder refuses more.
const MAX_TWIST: i32 = 180;

/// Frames whose middle angle is within this of ±90° (degrees) are near lock: there `a` and
/// `c` are ill-conditioned enough that a rotation within a bound can put them tens of
/// degrees off; farther out a twist would only move the rotation.
const LOCK: f64 = 15.0;

/// A twist must bring the triple this much nearer the file's than none (degrees, summed
/// over the three angles, each on its nearest branch), and a twist in use is kept while it
/// is within this of the best one, so a joint resting near lock does not pay for a new
/// twist every frame.
pub const SLACK: f64 = 15.0;

/// A twist is taken only where the triple without one is farther than this from the
/// file's (degrees, summed): nearer, no curve jumps for it, and the twist's move of the
/// rotation would cost bits for nothing (`rot` +0.6 % at 1 mm without this floor, +0.3 %
/// with it, over the corpus BVH).
const FAR: f64 = 30.0;

/// Twists are for rotations within this of the file's (degrees): a bound on positions keeps
/// a seen rotation far nearer, and one farther off is off where no position shows.
const OWN: f64 = 2.0;

/// A twist in use must stay as near the file's as no twist, give or take this (degrees):
/// rounding never forces a change.
const GAIN: f64 = 1e-3;

/// Where the file's first or last angle turns by more than this between two frames
/// (degrees, either side of the frame), the file's curve nearly jumps (its jumps are over
/// 90°): a decoded triple a few degrees off there can make a jump the file does not have,
/// so such frames are held to [`TIGHT`] instead of [`FAR`] and [`SLACK`] (Bandai walkers
/// turned 79–90° in a frame and decoded 91–95°).
const TURN: f64 = 60.0;

/// How near the file's a frame at a [`TURN`] is put (degrees, summed): a twist is taken
/// when it brings the triple this much nearer, and one in use is kept only within this of
/// the best.
const TIGHT: f64 = 1.0;

/// The sign σ with which the last angle joins the first near lock: with `Rb(b) e_c =
/// ±e_a`, `Ra(a) Rb(b) Rc(c) = Ra(a + σc) Rb(b)`, σ = sign(sin b) times the order's parity
/// (`e_a · (e_b × e_c)`, +1 for xyz, yzx and zxy).
pub fn sigma(order: [usize; 3], b: f64) -> f64 {
    let parity = if (order[1] + 3 - order[0]) % 3 == 1 {
        1.0
    } else {
        -1.0
    };
    // sin b ≥ 0 for b in [0°, 180°) modulo 360° (IEEE basic operations, no library's sine).
    if b.rem_euclid(360.0) < 180.0 {
        parity
    } else {
        -parity
    }
}

/// `e` twisted by `t` degrees.
pub fn twisted(e: [f64; 3], order: [usize; 3], t: i32) -> [f64; 3] {
    if t == 0 {
        return e;
    }
    let t = f64::from(t);
    [e[0] + t, e[1], e[2] - sigma(order, e[1]) * t]
}

/// Whether `e`'s middle angle is near lock: within [`LOCK`] of 90° modulo 180°. IEEE basic
/// operations (correctly rounded on every machine), not a library's cosine: the decoder
/// reads a symbol or not by this, and every machine must decide alike.
fn near_lock(e: [f64; 3]) -> bool {
    (e[1].rem_euclid(180.0) - 90.0).abs() < LOCK
}

/// An angle difference, wrapped into (−180°, 180°].
fn wrapped(d: f64) -> f64 {
    let d = d.rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

/// How far `e` is from `target` on its nearest branch (flipped or not, whole turns per
/// angle): the sum of absolute angle differences, degrees.
fn off(e: [f64; 3], target: [f64; 3]) -> f64 {
    let flipped = [e[0] + 180.0, 180.0 - e[1], e[2] + 180.0];
    [e, flipped]
        .iter()
        .map(|y| (0..3).map(|k| wrapped(target[k] - y[k]).abs()).sum::<f64>())
        .fold(f64::INFINITY, f64::min)
}

/// A chunk's twists: each joint's twist in use and the chunk's adaptive models.
#[derive(Debug, Clone)]
pub struct Twists {
    twist: Vec<i32>,
    change: Bit,
    value: IntModel,
}

impl Twists {
    /// For a chunk of `joints` joints (any index the caller uses below `joints`).
    pub fn new(joints: usize) -> Twists {
        Twists {
            twist: vec![0; joints],
            change: Bit::default(),
            value: IntModel::default(),
        }
    }

    /// Joint `j`'s decoded triple `e` (about `order`'s axes) of one frame, twisted as the
    /// chunk says (as the encoder decides from `source`, the file's triple).
    pub fn code<I: Io>(
        &mut self,
        io: &mut I,
        j: usize,
        order: [usize; 3],
        e: [f64; 3],
        source: Option<Source>,
    ) -> Result<[f64; 3]> {
        if !near_lock(e) {
            self.twist[j] = 0;
            return Ok(e);
        }
        let current = self.twist[j];
        let want = match source {
            Some(s) if io.encoding() => decide(current, order, e, s),
            _ => current,
        };
        if io.bit(&mut self.change, want != current) {
            let t = io.int(&mut self.value, want);
            if t.abs() > MAX_TWIST {
                return Err(malformed(format!("a twist of {t}°")));
            }
            self.twist[j] = t;
        }
        Ok(twisted(e, order, self.twist[j]))
    }
}

/// The file's channel values of a chunk (`frames × channels`) with the frame before it and
/// the frame after it where the take has them: whether the file's curves turn at a chunk's
/// first or last frame is judged across the chunk's edge.
#[derive(Debug, Clone, Copy)]
pub struct Around<'a> {
    values: &'a [f64],
    channels: usize,
    /// The chunk's first frame in `values`.
    first: usize,
    frames: usize,
}

impl<'a> Around<'a> {
    /// The chunk of `frames` frames from frame `f0` of the take's `values`.
    pub fn new(values: &'a [f64], channels: usize, f0: usize, frames: usize) -> Around<'a> {
        let total = values.len() / channels.max(1);
        let start = f0.saturating_sub(1);
        let end = (f0 + frames + 1).min(total);
        Around {
            values: &values[start * channels..end * channels],
            channels,
            first: f0 - start,
            frames,
        }
    }

    /// The chunk's own values.
    pub fn chunk(&self) -> &'a [f64] {
        &self.values[self.first * self.channels..(self.first + self.frames) * self.channels]
    }

    /// What frame `f` of the chunk is judged by, for the joint at channels `idx`.
    pub fn source(&self, idx: [usize; 3], f: usize) -> Source {
        let triple = |r: usize| idx.map(|i| self.values[r * self.channels + i]);
        let r = self.first + f;
        let s = triple(r);
        let rows = self.values.len() / self.channels.max(1);
        let turns = [r.checked_sub(1), Some(r + 1).filter(|&n| n < rows)]
            .into_iter()
            .flatten()
            .any(|n| {
                let o = triple(n);
                [0, 2].iter().any(|&k| wrapped(o[k] - s[k]).abs() > TURN)
            });
        Source { s, turns }
    }
}

/// What the encoder judges a frame's twist by: the file's triple, and whether the file's
/// curves turn by more than [`TURN`] into or out of this frame.
#[derive(Debug, Clone, Copy)]
pub struct Source {
    s: [f64; 3],
    turns: bool,
}

/// A chunk's twists where nothing is aimed from the joints (`pga`): every frame of
/// `decoded` (`frames × channels`, as printed), joint by joint, judged against `source`
/// (the file's channel values) when encoding.
pub fn code_frames<I: Io>(
    io: &mut I,
    turnings: &[Turning],
    channels: usize,
    source: Option<Around>,
    decoded: &mut [f64],
) -> Result<()> {
    if channels == 0 {
        return Ok(());
    }
    let mut tw = Twists::new(turnings.len());
    for (f, row) in decoded.chunks_exact_mut(channels).enumerate() {
        for (j, t) in turnings.iter().enumerate() {
            let e = t.idx.map(|i| row[i]);
            let given = source.map(|s| s.source(t.idx, f));
            let shown = tw.code(io, j, t.order, e, given)?;
            if shown != e {
                for (k, i) in t.idx.iter().enumerate() {
                    row[*i] = printed(shown[k]);
                }
            }
        }
    }
    Ok(())
}

/// The encoder's twist for a frame near lock, `current` in use, judged by the file's.
fn decide(current: i32, order: [usize; 3], e: [f64; 3], given: Source) -> i32 {
    let s = given.s;
    let (far, slack) = if given.turns {
        (TIGHT, TIGHT)
    } else {
        (FAR, SLACK)
    };
    if !s.iter().chain(&e).all(|v| v.is_finite()) {
        return 0;
    }
    let target = from_euler(order, s);
    let own = from_euler(order, e).angle_to(&target);
    // A rotation this far off the file's is off by a turn no position shows (about a bone
    // its children lie on), not by ill-conditioning: a twist would move the rotation, not
    // its angles, and the file's triple must be near lock too.
    if !near_lock(s) || own > OWN.to_radians() {
        return 0;
    }
    let keeps = |t: i32| t == 0 || from_euler(order, twisted(e, order, t)).angle_to(&target) <= own;
    let dist = |t: i32| off(twisted(e, order, t), s);
    let plain = dist(0);
    // The twist that puts `a` on the file's, for either branch.
    let (best, near) = [0.0, 180.0]
        .iter()
        .map(|flip| {
            let t = wrapped(s[0] - e[0] - flip).round() as i32;
            let t = t.clamp(-MAX_TWIST, MAX_TWIST);
            (t, dist(t))
        })
        .fold((0, plain), |b, c| if c.1 < b.1 { c } else { b });
    let now = dist(current);
    if keeps(current) && now <= plain + GAIN && now <= near + slack {
        current
    } else if best != 0 && plain > far && near + slack < plain && keeps(best) {
        best
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::entropy::io::Dry;
    use crate::codec::entropy::rangecoder::{Decoder, Encoder};
    use crate::motion::rotation::to_euler;
    use nalgebra::{UnitQuaternion, Vector3};

    const ORDER: [usize; 3] = [2, 0, 1];

    #[test]
    fn sigma_joins_the_first_and_last_angles_at_lock() {
        for order in [
            [0, 1, 2],
            [2, 0, 1],
            [1, 2, 0],
            [0, 2, 1],
            [2, 1, 0],
            [1, 0, 2],
        ] {
            for b in [90.0, -90.0] {
                let e = [31.0, b, -12.0];
                let q = from_euler(order, e);
                let t = from_euler(order, twisted(e, order, 40));
                assert!(q.angle_to(&t) < 1e-12, "{order:?} {b}");
            }
        }
    }

    /// A joint passing near lock: the decoded rotations are a fraction of a degree from
    /// the file's, yet their first and last angles sit tens of degrees from the file's.
    fn near_lock_frames() -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let (mut source, mut decoded) = (Vec::new(), Vec::new());
        let mut near = None;
        for f in 0..60 {
            let x = f as f64;
            let src = [30.0 + 2.0 * x, 89.7 - 0.005 * x, -25.0 - 2.0 * x];
            let err = Vector3::new(0.3, -0.2, 0.1).normalize() * 0.3f64.to_radians();
            let q = from_euler(ORDER, src) * UnitQuaternion::from_scaled_axis(err);
            let e = to_euler(&q, ORDER, near);
            near = Some(e);
            source.push(src);
            decoded.push(e);
        }
        (source, decoded)
    }

    fn run<I: Io>(io: &mut I, source: &[[f64; 3]], decoded: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let mut tw = Twists::new(1);
        source
            .iter()
            .zip(decoded)
            .map(|(s, e)| {
                let given = Source {
                    s: *s,
                    turns: false,
                };
                tw.code(io, 0, ORDER, *e, io.encoding().then_some(given))
                    .unwrap()
            })
            .collect()
    }

    #[test]
    fn twists_put_triples_near_lock_on_the_files_angles_without_moving_rotations_away() {
        let (source, decoded) = near_lock_frames();
        let worst = |d: &[[f64; 3]]| {
            d.iter()
                .zip(&source)
                .map(|(d, s)| off(*d, *s))
                .fold(0.0, f64::max)
        };
        assert!(worst(&decoded) > 2.0 * FAR, "{}", worst(&decoded));
        let mut enc = Encoder::new();
        let enc_out = run(&mut enc, &source, &decoded);
        let bytes = enc.finish();
        let dec_out = run(&mut Decoder::new(&bytes), &source, &decoded);
        assert_eq!(dec_out, enc_out);
        assert_eq!(run(&mut Dry, &source, &decoded), enc_out);
        assert!(worst(&dec_out) <= FAR, "{}", worst(&dec_out));
        for ((d, e), s) in dec_out.iter().zip(&decoded).zip(&source) {
            let s = from_euler(ORDER, *s);
            let after = from_euler(ORDER, *d).angle_to(&s);
            let before = from_euler(ORDER, *e).angle_to(&s);
            assert!(after <= before, "{after} > {before}");
        }
        assert!(bytes.len() < 40, "{} bytes for 60 frames", bytes.len());
    }

    #[test]
    fn where_the_files_curve_nearly_jumps_the_triple_is_held_tight() {
        // Ten degrees off the file's (summed), the same rotation within 0.03°: left alone
        // on a quiet curve, put on the file's where the curve turns by nearly a jump.
        let s = [40.0, 89.7, -35.0];
        let e = twisted(s, ORDER, 5);
        assert!((off(e, s) - 10.0).abs() < 1e-9);
        assert!(from_euler(ORDER, e).angle_to(&from_euler(ORDER, s)) < 0.03f64.to_radians());
        for (turns, want) in [(false, e), (true, s)] {
            let mut enc = Encoder::new();
            let got = Twists::new(1)
                .code(&mut enc, 0, ORDER, e, Some(Source { s, turns }))
                .unwrap();
            assert!(
                off(got, want) < 1e-9,
                "turns {turns}: {got:?}, not {want:?}"
            );
        }
    }

    #[test]
    fn the_files_turns_are_judged_across_a_chunks_edges() {
        // One joint, first angle 0, 0, 80, 80, 80: the turn into frame 2 is seen from the
        // chunk that starts there, and from the one that ends just before.
        let values: Vec<f64> = [0.0, 0.0, 80.0, 80.0, 80.0]
            .iter()
            .flat_map(|a| [*a, 89.0, 0.0])
            .collect();
        let idx = [0, 1, 2];
        let late = Around::new(&values, 3, 2, 3);
        assert_eq!(late.chunk(), &values[6..]);
        let turns: Vec<bool> = (0..3).map(|f| late.source(idx, f).turns).collect();
        assert_eq!(turns, [true, false, false]);
        let early = Around::new(&values, 3, 0, 2);
        assert_eq!(early.chunk(), &values[..6]);
        let turns: Vec<bool> = (0..2).map(|f| early.source(idx, f).turns).collect();
        assert_eq!(turns, [false, true]);
    }

    #[test]
    fn away_from_lock_nothing_is_coded_or_moved() {
        let mut tw = Twists::new(2);
        let mut enc = Encoder::new();
        let empty = Encoder::new().finish();
        let e = [10.0, 40.0, -70.0];
        for _ in 0..50 {
            let given = Some(Source {
                s: [80.0, 40.0, -140.0],
                turns: true,
            });
            assert_eq!(tw.code(&mut enc, 1, ORDER, e, given).unwrap(), e);
        }
        assert_eq!(enc.finish(), empty);
    }

    #[test]
    fn damaged_twists_are_refused_or_finite() {
        let (_, decoded) = near_lock_frames();
        for seed in 0..200u32 {
            let bytes: Vec<u8> = (0..12)
                .map(|i| (seed.wrapping_mul(2654435761).rotate_left(i) >> 3) as u8)
                .collect();
            let mut tw = Twists::new(1);
            let mut dec = Decoder::new(&bytes);
            for e in &decoded {
                match tw.code(&mut dec, 0, ORDER, *e, None) {
                    Ok(t) => assert!(t.iter().all(|v| v.is_finite())),
                    Err(_) => break,
                }
            }
        }
    }
}
