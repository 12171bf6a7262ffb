//! Checks that codecs share in their unit tests.

use std::sync::Arc;

use super::pipeline::Encoded;
use super::{
    encode, ChunkDecoder, CodecId, EncodeOptions, ErrorBound, Reader, Shared, Skeleton, Stored,
};
use crate::motion::Motion;

/// `m` encoded with `codec` to `bound`, no options: the tests' usual encode.
pub fn encoded(m: &Motion, codec: CodecId, bound: ErrorBound) -> Encoded {
    encode(m, codec, bound, EncodeOptions::default())
        .unwrap_or_else(|e| panic!("{codec} {bound}: {e}"))
}

/// What a reader of a skeleton take `m` needs: its rig.
pub fn skeleton_shared(m: &Motion) -> Shared {
    Shared {
        basis: None,
        rig: Some(Arc::new(
            Skeleton::new(m.skeleton.clone().unwrap().joints).unwrap(),
        )),
    }
}

/// The first chunk of `enc` (a take of `m`): its frames and codec bytes.
pub fn first_chunk(enc: &Encoded, m: &Motion) -> (usize, Vec<u8>) {
    let frames = enc.container.header.chunks[0].frames as usize;
    let (_, bytes) =
        super::container::unpack_chunk(&enc.container.chunks[0], frames * m.point_count()).unwrap();
    (frames, bytes.to_vec())
}

/// Decode `bytes` with a byte flipped (each of the first 300 in turn) and cut short: each
/// gives channels or an error, never a panic.
pub fn damage_channels(d: &dyn ChunkDecoder, bytes: &[u8], frames: usize) {
    for i in 0..bytes.len().min(300) {
        let mut b = bytes.to_vec();
        b[i] ^= 0x5a;
        let _ = d.decode_channels(&b, frames);
    }
    for cut in [0, 1, bytes.len() / 2] {
        let _ = d.decode_channels(&bytes[..cut], frames);
    }
}

/// The max and mean error (mm) of `enc` against `m`, measured apart from the encoder's own
/// check (which `encode` passed before returning, so asserting its `stats` proves nothing):
/// the stored bytes serialised, parsed back and read by ranges of 37 frames that straddle
/// chunk boundaries (the encoder decodes whole chunks), every present point's distance
/// summed here; a gap must come back a gap.
pub fn measured(m: &Motion, enc: &Encoded) -> (f64, f64) {
    let bytes = enc.container.to_bytes();
    let container = super::Container::parse(&bytes, &super::DecodeLimits::default()).unwrap();
    let rig = m
        .skeleton
        .as_ref()
        .filter(|_| container.header.rig.is_some())
        .map(|s| Arc::new(Skeleton::new(s.joints.clone()).unwrap()));
    let reader = Reader::new(container.header.clone(), Shared { basis: None, rig }).unwrap();
    let source = Stored::new(0, container.chunks.iter().map(Vec::as_slice));
    let frames = m.frame_count();
    let mut got = Vec::with_capacity(m.positions().len());
    for start in (0..frames).step_by(37) {
        got.extend(
            reader
                .read(start..(start + 37).min(frames), None, &source)
                .unwrap(),
        );
    }
    let want = m.positions();
    assert_eq!(got.len(), want.len());
    let (mut max, mut sum, mut n) = (0f64, 0f64, 0usize);
    for (a, b) in want.chunks_exact(3).zip(got.chunks_exact(3)) {
        if a[0].is_nan() {
            assert!(b[0].is_nan(), "a gap decoded as {b:?}");
            continue;
        }
        let d = a
            .iter()
            .zip(b)
            .map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(d.is_finite(), "decoded {b:?} for {a:?}");
        max = max.max(d);
        sum += d;
        n += 1;
    }
    let mm = m.unit.to_mm();
    (max * mm, sum / n.max(1) as f64 * mm)
}

/// `codec` meets each max bound of `bounds` (mm) on `m`'s FK positions, close under it
/// rather than far below, with fewer bytes as bounds loosen; and a mean bound of 2 mm. Each
/// error [`measured`] from the stored bytes.
pub fn meets_bounds_and_shrinks(m: &Motion, codec: CodecId, bounds: [f64; 3]) {
    let mut last = usize::MAX;
    for mm in bounds {
        let enc = encoded(m, codec, ErrorBound::max(mm));
        let (max, _) = measured(m, &enc);
        assert!(max <= mm, "{max} > {mm}");
        // The search lands close under the bound, not far below it.
        assert!(max > 0.5 * mm, "{max} ≪ {mm}");
        assert!(enc.stored_bytes < last);
        last = enc.stored_bytes;
    }
    let enc = encoded(m, codec, ErrorBound::mean(2.0));
    let (_, mean) = measured(m, &enc);
    assert!(mean <= 2.0, "{mean} > 2");
}

/// Skeleton take `m` (`cc` channels) coded by `codec` at 1 mm: its decoded channel values.
fn channels_at_1mm(m: &Motion, codec: CodecId, cc: usize) -> Vec<f64> {
    let enc = encoded(m, codec, ErrorBound::max(1.0));
    let source = Stored::new(0, enc.container.chunks.iter().map(Vec::as_slice));
    Reader::new(enc.container.header.clone(), skeleton_shared(m))
        .and_then(|r| r.read_channels(0..m.frame_count(), cc, &source))
        .unwrap()
        .values
}

/// A dancer whose Euler triples are moved, joint by joint and 40 frames at a time, to
/// equivalent ones (the other branch, whole turns), as exporters write them; coded by
/// `codec` at 1 mm, every decoded triple must be the source's (within a few degrees) and
/// the decoded channels must jump no more often than the source's.
pub fn follows_the_sources_euler_branches(codec: CodecId) {
    let mut m = crate::motion::synthetic::dancer(240, 60.0, 5);
    let sk = m.skeleton.as_mut().unwrap();
    let cc = sk.joints.iter().map(|j| j.channels.len()).sum::<usize>();
    let turnings = super::branches::turnings(&Skeleton::new(sk.joints.clone()).unwrap());
    assert!(turnings.len() > 3);
    for (n, t) in turnings.iter().enumerate() {
        for (f, row) in sk.values.chunks_exact_mut(cc).enumerate() {
            if (f / 40 + n) % 2 == 0 {
                let [a, b, c] = t.idx;
                row[a] += 180.0 + 360.0 * (n % 3) as f64;
                row[b] = 180.0 - row[b];
                row[c] -= 180.0;
            }
        }
    }
    let sk = m.skeleton.clone().unwrap();
    let decoded = channels_at_1mm(&m, codec, cc);
    let rot: Vec<usize> = turnings.iter().flat_map(|t| t.idx).collect();
    let largest = decoded
        .chunks_exact(cc)
        .zip(sk.values.chunks_exact(cc))
        .flat_map(|(d, s)| rot.iter().map(move |&c| (d[c] - s[c]).abs()))
        .fold(0.0, f64::max);
    assert!(
        largest < 5.0,
        "{codec}: a decoded angle {largest}° off the source's"
    );
    let jumps = |v: &[f64]| {
        let rows: Vec<&[f64]> = v.chunks_exact(cc).collect();
        rows.windows(2)
            .map(|w| {
                rot.iter()
                    .filter(|&&c| (w[1][c] - w[0][c]).abs() > 90.0)
                    .count()
            })
            .sum::<usize>()
    };
    let (s, d) = (jumps(&sk.values), jumps(&decoded));
    assert!(
        s > 0 && d <= s,
        "{codec}: {d} jumps against the source's {s}"
    );
}

/// A dancer with two joints held near gimbal lock ([`dancer_near_lock`]): coded by `codec`
/// at 1 mm, their decoded triples stay near the file's ([`twists`](super::twists)); a
/// rotation within the bound alone leaves them tens of degrees off (89° and 57° here,
/// `rot` and `pga`).
///
/// [`dancer_near_lock`]: crate::motion::synthetic::dancer_near_lock
pub fn keeps_the_sources_angles_near_gimbal_lock(codec: CodecId) {
    let m = crate::motion::synthetic::dancer_near_lock(240, 60.0, 7);
    let sk = m.skeleton.clone().unwrap();
    let cc = sk.joints.iter().map(|j| j.channels.len()).sum::<usize>();
    let turnings = super::branches::turnings(&Skeleton::new(sk.joints.clone()).unwrap());
    let held: Vec<_> = turnings
        .iter()
        .filter(|t| sk.values.chunks_exact(cc).all(|r| r[t.idx[1]].abs() > 89.7))
        .collect();
    assert_eq!(held.len(), 2);
    let decoded = channels_at_1mm(&m, codec, cc);
    let largest = decoded
        .chunks_exact(cc)
        .zip(sk.values.chunks_exact(cc))
        .flat_map(|(d, s)| {
            held.iter()
                .flat_map(|t| t.idx)
                .map(move |c| (d[c] - s[c]).abs())
        })
        .fold(0.0, f64::max);
    assert!(
        largest < 30.0,
        "{codec}: a decoded angle near lock {largest}° off the source's"
    );
}
