//! PPCA segmentation on real takes: two very different corpus takes joined end to end are
//! cut within half a second of the join (an acceptance test of the `spca` issue).

use mocapstore::codec::segment::{cuts, Params};
use mocapstore::corpus;
use mocapstore::motion::formats::{self, ReadOptions};
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
