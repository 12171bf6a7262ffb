//! `mocapstore bench --lossless`: `bvh-lossless` against the general-purpose compressors a
//! BVH archive would otherwise use (xz -9e, zstd -19, gzip -9), file by file, on the same
//! text. xz and gzip are the system's programs (a missing one is reported and left out);
//! zstd is the library the service already links.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::time::Instant;

use mocapstore::codec::{self, CodecId, ErrorBound};
use mocapstore::motion::formats::{self, Format};

/// Bytes of `data` through an external compressor, or `None` if it cannot be run.
pub(super) fn external(program: &str, args: &[&str], data: &[u8]) -> Option<usize> {
    let mut child = Command::new(program)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .ok()?;
    let mut stdin = child.stdin.take()?;
    let input = data.to_vec();
    let writer = std::thread::spawn(move || stdin.write_all(&input));
    let out = child.wait_with_output().ok()?;
    writer.join().ok()?.ok()?;
    out.status.success().then_some(out.stdout.len())
}

/// One file's sizes: text, bvh-lossless, xz, zstd, gzip.
struct Sizes {
    file: String,
    frames: usize,
    text: usize,
    ours: usize,
    xz: Option<usize>,
    zstd: usize,
    gzip: Option<usize>,
}

pub fn run(files: &[PathBuf], out: &Path) -> ExitCode {
    let mut rows = Vec::new();
    let (mut encode_s, mut decode_s) = (0f64, 0f64);
    for path in files
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
    {
        let Ok(bytes) = std::fs::read(path) else {
            continue;
        };
        let Ok(loaded) = formats::read_as(Format::Bvh, &bytes, &Default::default()) else {
            eprintln!("{}: not readable, left out", path.display());
            continue;
        };
        let m = loaded.motion;
        let t0 = Instant::now();
        let enc = match codec::encode(
            &m,
            CodecId::BvhLossless,
            ErrorBound::max(0.0),
            codec::EncodeOptions::default(),
        ) {
            Ok(e) => e,
            Err(e) => {
                eprintln!("{}: {e}", path.display());
                continue;
            }
        };
        encode_s += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let rig = std::sync::Arc::new(
            codec::Skeleton::new(
                m.skeleton
                    .clone()
                    .expect("a BVH take has a skeleton")
                    .joints,
            )
            .expect("a parsed skeleton is valid"),
        );
        let shared = codec::Shared {
            basis: None,
            rig: Some(rig),
        };
        if codec::decode_all_with(&enc.container, shared).is_err() {
            eprintln!("{}: does not decode", path.display());
            return ExitCode::FAILURE;
        }
        decode_s += t0.elapsed().as_secs_f64();
        rows.push(Sizes {
            file: super::short_name(path),
            frames: m.frame_count(),
            text: bytes.len(),
            ours: enc.stored_bytes,
            xz: external("xz", &["-9e", "-c"], &bytes),
            zstd: zstd::encode_all(&bytes[..], 19).map_or(usize::MAX, |z| z.len()),
            gzip: external("gzip", &["-9", "-c"], &bytes),
        });
    }
    if rows.is_empty() {
        eprintln!("mocapstore bench --lossless: no readable BVH files");
        return ExitCode::FAILURE;
    }
    let opt = |v: Option<usize>| v.map_or("–".to_string(), |v| v.to_string());
    let ratio = |a: Option<usize>, b: usize| {
        a.map_or("–".to_string(), |a| format!("{:.2}", a as f64 / b as f64))
    };
    let mut table = String::from(
        "| file | frames | text | bvh-lossless | xz -9e | zstd -19 | gzip -9 | xz ÷ ours |\n|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in &rows {
        table += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.file,
            r.frames,
            r.text,
            r.ours,
            opt(r.xz),
            r.zstd,
            opt(r.gzip),
            ratio(r.xz, r.ours)
        );
    }
    let sum = |f: &dyn Fn(&Sizes) -> Option<usize>| -> Option<usize> {
        rows.iter().map(f).sum::<Option<usize>>()
    };
    let (text, ours) = (
        sum(&|r| Some(r.text)).unwrap_or(0),
        sum(&|r| Some(r.ours)).unwrap_or(0),
    );
    let (xz, zs, gz) = (sum(&|r| r.xz), sum(&|r| Some(r.zstd)), sum(&|r| r.gzip));
    let frames: usize = rows.iter().map(|r| r.frames).sum();
    table += &format!(
        "| **total ({} files)** | {frames} | {text} | {ours} | {} | {} | {} | {} |\n",
        rows.len(),
        opt(xz),
        opt(zs),
        opt(gz),
        ratio(xz, ours)
    );
    let smaller = rows
        .iter()
        .filter_map(|r| r.xz.map(|x| x as f64 / r.ours as f64))
        .collect::<Vec<_>>();
    let worst = smaller.iter().cloned().fold(f64::INFINITY, f64::min);
    let summary = format!(
        "bvh-lossless: {ours} bytes of {text} ({:.2}× the text; xz -9e {}, zstd -19 {}, gzip -9 {}); \
         per file {:.2}–{:.2}× smaller than xz -9e; encode {:.0} frames/s, decode {:.0} frames/s\n",
        text as f64 / ours as f64,
        opt(xz),
        opt(zs),
        opt(gz),
        worst,
        smaller.iter().cloned().fold(0.0, f64::max),
        frames as f64 / encode_s,
        frames as f64 / decode_s,
    );
    print!("{table}\n{summary}");
    if let Err(e) = std::fs::create_dir_all(out)
        .and_then(|_| std::fs::write(out.join("lossless.md"), format!("{table}\n{summary}")))
    {
        eprintln!("mocapstore bench: {}: {e}", out.display());
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
