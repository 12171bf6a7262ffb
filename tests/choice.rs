//! Per-take choice with a history (`service::history`) on a real library: the Bandai Namco
//! takes of the corpus, one layout, ingested in order at max 1 mm with every candidate that
//! keeps the animation (the default for BVH). Every take is encoded with every candidate
//! here, so what pruning left out is known: the bytes it cost, and how close the estimates
//! of the pruned candidates came.

use std::collections::BTreeMap;

use mocapstore::codec::{self, CodecId, ErrorBound};
use mocapstore::corpus;
use mocapstore::motion::formats::{self, ReadOptions};
use mocapstore::service::history::{Histories, Key};

/// How close the estimates of a pruned candidate come to its real size: 90 % of them within
/// this ratio either way, all of them within twice it. `pga`'s size follows `rot`'s closely;
/// a lossless coder's follows the file's printed precision, not the motion, and an
/// estimate from the history of its ratio to `rot` is looser.
const ESTIMATE_TOLERANCE: [(CodecId, f64); 2] = [(CodecId::Pga, 1.25), (CodecId::BvhLossless, 2.0)];

#[test]
fn pruning_by_history_costs_no_byte_at_keep_animation_and_estimates_hold() {
    let Some((root, manifest)) = corpus::for_tests() else {
        return;
    };
    let mut paths: Vec<_> = manifest
        .iter()
        .filter(|e| e.path.starts_with("bvh/bandai/"))
        .map(|e| e.path.clone())
        .collect();
    paths.sort();
    assert!(paths.len() >= 150, "{} Bandai takes", paths.len());
    let candidates = [CodecId::BvhLossless, CodecId::Rot, CodecId::Pga];
    let bound = ErrorBound::max(1.0);
    // Every take with every candidate, on two threads.
    let sizes: Vec<BTreeMap<CodecId, usize>> = std::thread::scope(|s| {
        let halves: Vec<_> = paths
            .chunks(paths.len().div_ceil(2))
            .map(|part| {
                s.spawn(|| {
                    part.iter()
                        .map(|p| {
                            let bytes = std::fs::read(root.join(p)).unwrap();
                            let m = formats::read(&bytes, &ReadOptions::default())
                                .unwrap()
                                .motion;
                            candidates
                                .iter()
                                .filter(|c| codec::codec(**c).unwrap().unsuited(&m).is_none())
                                .filter_map(|&c| {
                                    codec::encode(&m, c, bound, codec::EncodeOptions::default())
                                        .ok()
                                        .map(|e| (c, e.stored_bytes))
                                })
                                .collect()
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        halves.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });

    let h = Histories::default();
    let key = Key {
        layout: "bandai".into(),
        bound: bound.to_string(),
        rules: "sequence, keep animation".into(),
        bases: Vec::new(),
    };
    let (mut best_all, mut best_kept, mut planned_out) = (0usize, 0usize, 0usize);
    let mut ratios: BTreeMap<CodecId, Vec<f64>> = BTreeMap::new();
    for s in &sizes {
        let present: Vec<CodecId> = s.keys().copied().collect();
        let plan = h.plan(&key, &present);
        let kept = plan
            .run
            .iter()
            .filter_map(|c| s.get(c))
            .min()
            .copied()
            .unwrap();
        best_all += s.values().min().unwrap();
        best_kept += kept;
        planned_out += plan.pruned.len();
        for p in &plan.pruned {
            let estimate = kept as f64 * p.median_ratio;
            ratios
                .entry(p.codec)
                .or_default()
                .push(s[&p.codec] as f64 / estimate);
        }
        if plan.explore {
            h.record(&key, s.clone());
        }
    }
    let lost = best_kept as f64 / best_all as f64 - 1.0;
    println!(
        "{} takes: {planned_out} candidate encodings left out, bytes +{:.3} %",
        sizes.len(),
        100.0 * lost
    );
    // The README's promise: at keep=animation, pruning costs no byte on these takes.
    assert_eq!(
        best_kept,
        best_all,
        "pruning cost {:.3} % of the bytes; the README says none",
        100.0 * lost
    );
    // The point of it: after the exploration, most takes skip most losing candidates.
    assert!(
        planned_out >= sizes.len(),
        "only {planned_out} encodings left out over {} takes",
        sizes.len()
    );
    for (codec, r) in &ratios {
        let mut sorted = r.clone();
        sorted.sort_by(f64::total_cmp);
        let q = |p: f64| sorted[((sorted.len() - 1) as f64 * p).round() as usize];
        println!(
            "{codec}: {} estimates, real/estimate p5 {:.2} p50 {:.2} p95 {:.2}, min {:.2} max {:.2}",
            r.len(),
            q(0.05),
            q(0.5),
            q(0.95),
            sorted[0],
            sorted[sorted.len() - 1]
        );
        let t = ESTIMATE_TOLERANCE
            .iter()
            .find(|(c, _)| c == codec)
            .map(|(_, t)| *t)
            .unwrap_or_else(|| panic!("{codec} was pruned; state its tolerance"));
        let within = |t: f64| r.iter().filter(|&&x| x <= t && x >= 1.0 / t).count();
        assert!(
            within(t) as f64 >= 0.9 * r.len() as f64,
            "{codec}: {} of {} within ×/÷{t}",
            within(t),
            r.len()
        );
        assert_eq!(within(2.0 * t), r.len(), "{codec}");
    }
}
