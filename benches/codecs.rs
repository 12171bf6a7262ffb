//! Codec speed on a real take (CMU 01_03, 31 joints + 7 end sites, 120 fps, 4511 frames):
//! decode frames/s per codec and bound, and MDTT's fixed-parameter encode (the paper's
//! setting, no search) next to the rate-controlled one.
//! Run: `cargo bench --bench codecs` (MOCAP_CORPUS points at the corpus).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use mocapstore::codec::{self, mdtt, CodecId, ErrorBound, Input, Target};
use mocapstore::corpus;
use mocapstore::motion::formats::{read, ReadOptions};

fn take() -> mocapstore::motion::Motion {
    let path = corpus::root().join("bvh/cmu/01_03.bvh");
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    read(&bytes, &ReadOptions::default()).expect("loads").motion
}

fn decode(c: &mut Criterion) {
    let m = take();
    let mut g = c.benchmark_group("decode_cmu_01_03");
    g.sample_size(20);
    g.throughput(Throughput::Elements(m.frame_count() as u64));
    for (codec, bound) in [
        (CodecId::Raw, ErrorBound::MaxMm(1.0)),
        (CodecId::Quant, ErrorBound::MaxMm(1.0)),
        (CodecId::Quant, ErrorBound::MeanMm(3.0)),
        (CodecId::Mdtt, ErrorBound::MaxMm(1.0)),
        (CodecId::Mdtt, ErrorBound::MeanMm(3.0)),
    ] {
        let enc = codec::encode(&m, codec, bound).expect("encodes");
        g.bench_function(format!("{codec} {bound}"), |b| {
            b.iter(|| codec::decode_all(&enc.container).unwrap())
        });
    }
    g.finish();
}

fn encode(c: &mut Criterion) {
    let m = take();
    let filled = m.positions().to_vec();
    let mm = m.unit.to_mm();
    let input = Input {
        data: &filled,
        valid: None,
        frames: m.frame_count(),
        points: m.point_count(),
        fps: m.fps,
        shared: None,
    };
    let mut g = c.benchmark_group("encode_cmu_01_03");
    g.sample_size(10);
    g.throughput(Throughput::Elements(m.frame_count() as u64));
    // The paper's setting: one rank, one step, no search; k = 30 at a 3 mm-ish step.
    g.bench_function("mdtt fixed k=30 (paper setting)", |b| {
        b.iter(|| mdtt::encode_with(&input, 30, 3.0 / mm, Target::Mean(3.0 / mm)).unwrap())
    });
    g.bench_function("mdtt rate-controlled mean 3 mm", |b| {
        b.iter(|| codec::encode(&m, CodecId::Mdtt, ErrorBound::MeanMm(3.0)).unwrap())
    });
    g.bench_function("quant rate-controlled max 1 mm", |b| {
        b.iter(|| codec::encode(&m, CodecId::Quant, ErrorBound::MaxMm(1.0)).unwrap())
    });
    g.finish();
}

criterion_group!(benches, decode, encode);
criterion_main!(benches);
