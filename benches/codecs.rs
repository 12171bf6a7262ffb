//! Codec speed on a real take (CMU 01_03, 31 joints + 7 end sites, 120 fps, 4511 frames):
//! decode frames/s per codec and bound, and MDTT's fixed-parameter encode (the paper's
//! setting, no search) next to the rate-controlled one.
//! Run: `cargo bench --bench codecs` (MOCAP_CORPUS points at the corpus).

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use mocapstore::codec::lsdt::train::{train_basis, TrainOptions};
use mocapstore::codec::mdtt::database::{train_bases, SetOptions};
use mocapstore::codec::{self, mdtt, CodecId, ErrorBound, Input, Target};
use mocapstore::corpus;
use mocapstore::motion::formats::{read, ReadOptions};

fn take() -> mocapstore::motion::Motion {
    load("01_03")
}

fn load(name: &str) -> mocapstore::motion::Motion {
    let path = corpus::root().join(format!("bvh/cmu/{name}.bvh"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    read(&bytes, &ReadOptions::default()).expect("loads").motion
}

fn decode(c: &mut Criterion) {
    let m = take();
    let mut g = c.benchmark_group("decode_cmu_01_03");
    g.sample_size(20);
    g.throughput(Throughput::Elements(m.frame_count() as u64));
    for (codec, bound) in [
        (CodecId::Raw, ErrorBound::max(1.0)),
        (CodecId::Quant, ErrorBound::max(1.0)),
        (CodecId::Quant, ErrorBound::mean(3.0)),
        (CodecId::Mdtt, ErrorBound::max(1.0)),
        (CodecId::Mdtt, ErrorBound::mean(3.0)),
    ] {
        let enc =
            codec::encode(&m, codec, bound, codec::EncodeOptions::default()).expect("encodes");
        g.bench_function(format!("{codec} {bound}"), |b| {
            b.iter(|| codec::decode_all(&enc.container).unwrap())
        });
    }
    // Shared-basis codecs, with bases trained on another take of the layout (CMU 01_01).
    let other = load("01_01");
    let lsdt = Arc::new(
        train_basis(
            &[other.positions()],
            other.point_count(),
            &TrainOptions::default(),
            50_000,
        )
        .expect("trains")
        .basis,
    );
    let filled = codec::gaps::fill(other.positions(), other.point_count());
    let input = Input {
        data: &filled,
        valid: None,
        frames: other.frame_count(),
        points: other.point_count(),
        fps: other.fps,
        shared: None,
        skeleton: None,
        names: &[],
        torso: None,
    };
    let set = Arc::new(train_bases(&[input], 4, &SetOptions::default()).expect("trains"));
    for (codec, bound, basis) in [
        (CodecId::LsdtFrame, ErrorBound::max(1.0), &lsdt),
        (CodecId::LsdtFrame, ErrorBound::mean(3.0), &lsdt),
        (CodecId::LsdtClip, ErrorBound::max(1.0), &lsdt),
        (CodecId::LsdtClip, ErrorBound::mean(3.0), &lsdt),
        (CodecId::MdttShared, ErrorBound::max(1.0), &set),
        (CodecId::MdttShared, ErrorBound::mean(3.0), &set),
    ] {
        let enc = codec::encode(
            &m,
            codec,
            bound,
            codec::EncodeOptions::with_basis(Some(basis)),
        )
        .expect("encodes");
        let reader = codec::Reader::new(enc.container.header.clone(), Some(basis.clone())).unwrap();
        let chunks = codec::Stored::new(0, enc.container.chunks.iter().map(Vec::as_slice));
        g.bench_function(format!("{codec} {bound}"), |b| {
            b.iter(|| reader.read_all(&chunks).unwrap())
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
        skeleton: None,
        names: &[],
        torso: None,
    };
    let mut g = c.benchmark_group("encode_cmu_01_03");
    g.sample_size(10);
    g.throughput(Throughput::Elements(m.frame_count() as u64));
    // The paper's setting: one rank, one step, no search; k = 30 at a 3 mm-ish step.
    g.bench_function("mdtt fixed k=30 (paper setting)", |b| {
        b.iter(|| {
            mdtt::encode_with(
                &input,
                30,
                3.0 / mm,
                Target {
                    max: 30.0 / mm,
                    mean: Some(3.0 / mm),
                },
            )
            .unwrap()
        })
    });
    g.bench_function("mdtt rate-controlled mean 3 mm", |b| {
        b.iter(|| {
            codec::encode(
                &m,
                CodecId::Mdtt,
                ErrorBound::mean(3.0),
                codec::EncodeOptions::default(),
            )
            .unwrap()
        })
    });
    g.bench_function("quant rate-controlled max 1 mm", |b| {
        b.iter(|| {
            codec::encode(
                &m,
                CodecId::Quant,
                ErrorBound::max(1.0),
                codec::EncodeOptions::default(),
            )
            .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, decode, encode);
criterion_main!(benches);
