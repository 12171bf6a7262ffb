//! PPCA segmentation on real takes (acceptance tests of the `spca` issue): two very
//! different corpus takes joined end to end are cut within half a second of the join, and
//! `spca`'s segments hand over without a velocity spike.

use mocapstore::codec::segment::{cuts, Params};
use mocapstore::codec::{self, CodecId, ErrorBound};
use mocapstore::corpus;
use mocapstore::motion::formats::{self, ReadOptions};
use mocapstore::motion::metrics::{accelerations, speeds};
use mocapstore::motion::Motion;

fn take(path: &str) -> Option<Motion> {
    let (root, _) = corpus::for_tests()?;
    let bytes = std::fs::read(root.join(path)).unwrap_or_else(|e| panic!("{path}: {e}"));
    Some(
        formats::read(&bytes, &ReadOptions::default())
            .unwrap()
            .motion,
    )
}

/// Each frame's points relative to its first point (the root), as f64: the pose without
/// where the body stands, so the join is not found by a jump in position alone.
fn poses(m: &Motion, frames: usize) -> Vec<f64> {
    let w = m.point_count() * 3;
    let mut out = Vec::with_capacity(frames * w);
    for f in 0..frames {
        let row = &m.positions()[f * w..(f + 1) * w];
        for (i, v) in row.iter().enumerate() {
            out.push(f64::from(v - row[i % 3]));
        }
    }
    out
}

/// The first 5 s of a playground climb (CMU 01_01: no cut of its own) then the first 5 s of
/// a dance (CMU 131_02), root-relative: a cut within half a second of the join.
#[test]
fn two_different_takes_joined_are_cut_near_the_join() {
    let (Some(a), Some(b)) = (take("bvh/cmu/01_01.bvh"), take("bvh/cmu/131_02.bvh")) else {
        return;
    };
    assert_eq!(a.point_count(), b.point_count());
    assert_eq!(a.fps, b.fps);
    let n = (5.0 * a.fps) as usize;
    let width = a.point_count() * 3;
    let p = Params::at(a.fps);
    let first = poses(&a, n);
    assert_eq!(
        cuts(&first, width, &p),
        Vec::<usize>::new(),
        "the climb alone"
    );
    let mut data = first;
    data.extend(poses(&b, n));
    let found = cuts(&data, width, &p);
    let half_second = (a.fps / 2.0).round() as usize;
    assert!(
        found.iter().any(|&c| c.abs_diff(n) <= half_second),
        "cuts {found:?}, the join is at frame {n}"
    );
}

/// Every corpus BVH take coded with `spca` under a mean bound (no residual layer: the models
/// alone make the frames): where one segment hands over to the next, the decoded motion
/// moves no faster than the original does anywhere. (Accelerations are printed, not held
/// to the original's: in a slow take a step of a fraction of the bound at a hand-over is
/// already a sharper turn than any in the original.)
#[test]
fn spca_segments_hand_over_without_a_velocity_spike() {
    let Some((root, manifest)) = corpus::for_tests() else {
        return;
    };
    let (mut takes, mut cuts_seen, mut worst) = (0, 0, 0.0f64);
    for e in manifest.iter().filter(|e| e.path.starts_with("bvh/")) {
        let Ok(bytes) = std::fs::read(root.join(&e.path)) else {
            continue;
        };
        let Ok(m) = formats::read(&bytes, &ReadOptions::default()).map(|l| l.motion) else {
            continue;
        };
        let Ok(enc) = codec::encode(
            &m,
            CodecId::Spca,
            ErrorBound::mean(3.0),
            codec::EncodeOptions::default(),
        ) else {
            panic!("{}: spca refused it", e.path);
        };
        let chunks = &enc.container.header.chunks;
        if chunks.len() < 2 {
            continue;
        }
        takes += 1;
        let decoded = codec::decode_all(&enc.container).unwrap();
        let n = m.point_count();
        let max = |v: Vec<f64>| v.into_iter().fold(0.0, f64::max);
        let (vmax, amax) = (
            max(speeds(m.positions(), n)),
            max(accelerations(m.positions(), n)),
        );
        let (dv, da) = (speeds(&decoded, n), accelerations(&decoded, n));
        for c in &chunks[1..] {
            let b = c.first_frame as usize;
            cuts_seen += 1;
            assert!(
                dv[b - 1] <= vmax,
                "{} at {b}: speed {} > {vmax}",
                e.path,
                dv[b - 1]
            );
            for a in da.iter().take(b + 1).skip(b.saturating_sub(2)) {
                worst = worst.max(a / amax);
            }
        }
    }
    println!(
        "{cuts_seen} segment hand-overs in {takes} takes; the sharpest turn at one is {worst:.2}x \
         the original's sharpest"
    );
    assert!(cuts_seen > 0, "no corpus take was cut");
}
