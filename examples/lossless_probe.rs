use mocapstore::codec::{self, CodecId, ErrorBound};
use mocapstore::motion::formats::{read_as, ReadOptions};
use mocapstore::motion::format::Format;
fn main() {
    let dir = std::env::args().nth(1).unwrap();
    let mut files: Vec<_> = walk(std::path::Path::new(&dir));
    files.sort();
    let (mut tot_in, mut tot_out) = (0usize, 0usize);
    let t = std::time::Instant::now();
    let mut frames = 0;
    for f in files {
        let bytes = std::fs::read(&f).unwrap();
        let m = read_as(Format::Bvh, &bytes, &ReadOptions::default()).unwrap().motion;
        frames += m.frame_count();
        let enc = codec::encode(&m, CodecId::BvhLossless, ErrorBound::MaxMm(0.0)).unwrap();
        tot_in += bytes.len();
        tot_out += enc.stored_bytes;
        println!("{}\t{}\t{}", f.display(), bytes.len(), enc.stored_bytes);
    }
    eprintln!("total {tot_in} -> {tot_out}, {frames} frames, {:.1}s", t.elapsed().as_secs_f64());
}
fn walk(p: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(p).unwrap() {
        let e = e.unwrap().path();
        if e.is_dir() { v.extend(walk(&e)); } else if e.extension().is_some_and(|x| x == "bvh") { v.push(e); }
    }
    v
}
