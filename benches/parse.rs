//! Reader throughput on real files: BVH parse + FK on CMU 01_03, C3D load on the largest C3D with point data.
//! Run: `cargo bench --bench parse` (MOCAP_CORPUS points at the corpus).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use mocapstore::corpus;
use mocapstore::motion::formats::{read, ReadOptions};

fn bench_file(c: &mut Criterion, name: &str, rel: &str) {
    let path = corpus::root().join(rel);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let opts = ReadOptions::default();
    let frames = read(&bytes, &opts)
        .expect("corpus file loads")
        .motion
        .frame_count();
    let mut g = c.benchmark_group(name);
    g.sample_size(20);
    g.throughput(Throughput::Bytes(bytes.len() as u64));
    g.bench_function("bytes", |b| b.iter(|| read(&bytes, &opts).unwrap()));
    g.throughput(Throughput::Elements(frames as u64));
    g.bench_function("frames", |b| b.iter(|| read(&bytes, &opts).unwrap()));
    g.finish();
}

fn readers(c: &mut Criterion) {
    bench_file(c, "bvh_parse_fk_cmu_01_03", "bvh/cmu/01_03.bvh");
    bench_file(
        c,
        "c3d_load_largest",
        "c3d/c3dio__Codamotion__codamotion_gaitwands_20150204.c3d",
    );
}

criterion_group!(benches, readers);
criterion_main!(benches);
