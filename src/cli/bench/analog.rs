//! `mocapstore bench --analog`: `analog-lossless` against what a lab would otherwise use
//! for its force-plate and EMG channels: FLAC (`flac -8`, each channel as 16-bit PCM, for
//! the files that store integers) and `xz -9` of the analog block as the file stores it
//! (rows of 16-bit integers or floats), file by file, with encode and decode speed. `flac`
//! and `xz` are the system's programs (a missing one is reported as –).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use super::lossless::external;

use mocapstore::codec::analog;
use mocapstore::motion::analog::{Analog, Samples};
use mocapstore::motion::formats::{self, Format, ReadOptions};

/// The analog block as the file held it: rows of channels, 16-bit or f32, little-endian.
fn block(a: &Analog) -> Vec<u8> {
    match &a.samples {
        Samples::Int { values, .. } => values
            .iter()
            .flat_map(|&v| (v as u16).to_le_bytes())
            .collect(),
        Samples::Float(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

/// `flac -8` of every channel as mono 16-bit PCM, summed; `None` for float files or when
/// `flac` cannot be run.
fn flac(a: &Analog, rate: f64) -> Option<usize> {
    let Samples::Int { values, unsigned } = &a.samples else {
        return None;
    };
    let n = a.channel_count();
    let rate = format!("--sample-rate={}", (rate.round() as u64).clamp(1, 655_350));
    let sign = if *unsigned {
        "--sign=unsigned"
    } else {
        "--sign=signed"
    };
    let mut total = 0;
    for c in 0..n {
        let pcm: Vec<u8> = (0..a.rows())
            .flat_map(|r| (values[r * n + c] as u16).to_le_bytes())
            .collect();
        total += external(
            "flac",
            &[
                "-8",
                "--silent",
                "--no-padding",
                "--no-seektable",
                "--force-raw-format",
                "--endian=little",
                sign,
                "--channels=1",
                "--bps=16",
                &rate,
                "-c",
                "-",
            ],
            &pcm,
        )?;
    }
    Some(total)
}

struct Row {
    file: String,
    channels: usize,
    samples: usize,
    float: bool,
    raw: usize,
    ours: usize,
    flac: Option<usize>,
    xz: Option<usize>,
    encode_s: f64,
    decode_s: f64,
}

pub fn run(files: &[PathBuf], out: &Path) -> ExitCode {
    let lenient = ReadOptions {
        lenient: true,
        ..ReadOptions::default()
    };
    let mut rows = Vec::new();
    for path in files
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("c3d")))
    {
        let Ok(bytes) = std::fs::read(path) else {
            continue;
        };
        let Ok(loaded) = formats::read_as(Format::C3d, &bytes, &lenient) else {
            continue;
        };
        let Some(a) = loaded.extras.analog else {
            continue;
        };
        let fps = loaded.motion.fps;
        let frames = a.frames();
        let chunk = mocapstore::codec::default_chunk_frames(fps);
        // As the service chunks them: over point chunks of about a second.
        let point_chunks: Vec<usize> = (0..frames)
            .step_by(chunk)
            .map(|f| chunk.min(frames - f))
            .collect();
        let chunks = analog::chunk_frames(&point_chunks, a.per_frame);
        let t0 = Instant::now();
        let enc = match analog::encode(&a, fps, &chunks, &[]) {
            Ok(e) => e,
            Err(e) => {
                eprintln!("{}: {e}", path.display());
                return ExitCode::FAILURE;
            }
        };
        let encode_s = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        match analog::decode_all(&enc.container) {
            Ok(back) if back.samples.len() == a.samples.len() => {}
            _ => {
                eprintln!("{}: does not decode to what was coded", path.display());
                return ExitCode::FAILURE;
            }
        }
        let decode_s = t0.elapsed().as_secs_f64();
        rows.push(Row {
            file: super::short_name(path),
            channels: a.channel_count(),
            samples: a.samples.len(),
            float: matches!(a.samples, Samples::Float(_)),
            raw: a.raw_bytes(),
            ours: enc.container.stored_bytes(),
            flac: flac(&a, a.rate(fps)),
            xz: external("xz", &["-9", "-c"], &block(&a)),
            encode_s,
            decode_s,
        });
    }
    if rows.is_empty() {
        eprintln!("mocapstore bench --analog: no C3D files with analog channels");
        return ExitCode::FAILURE;
    }
    let opt = |v: Option<usize>| v.map_or("–".to_string(), |v| v.to_string());
    let mut table = String::from(
        "| file | channels | values | stored as | raw | analog-lossless | flac -8 | xz -9 | ours ÷ raw |\n|---|---:|---:|---|---:|---:|---:|---:|---:|\n",
    );
    for r in &rows {
        table += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {:.3} |\n",
            r.file,
            r.channels,
            r.samples,
            if r.float { "f32" } else { "i16" },
            r.raw,
            r.ours,
            opt(r.flac),
            opt(r.xz),
            r.ours as f64 / r.raw as f64
        );
    }
    let total = |f: &dyn Fn(&Row) -> usize| rows.iter().map(f).sum::<usize>();
    let (raw, ours, values) = (total(&|r| r.raw), total(&|r| r.ours), total(&|r| r.samples));
    let xz: Option<usize> = rows.iter().map(|r| r.xz).sum();
    table += &format!(
        "| **total ({} files)** | | {values} | | {raw} | {ours} | | {} | {:.3} |\n",
        rows.len(),
        opt(xz),
        ours as f64 / raw as f64
    );
    // FLAC reads only integers: compare on the files it can code.
    let ints: Vec<&Row> = rows.iter().filter(|r| r.flac.is_some()).collect();
    let (i_ours, i_flac, i_xz) = (
        ints.iter().map(|r| r.ours).sum::<usize>(),
        ints.iter().filter_map(|r| r.flac).sum::<usize>(),
        ints.iter().filter_map(|r| r.xz).sum::<usize>(),
    );
    let floats: Vec<&Row> = rows.iter().filter(|r| r.float).collect();
    let (f_ours, f_xz) = (
        floats.iter().map(|r| r.ours).sum::<usize>(),
        floats.iter().filter_map(|r| r.xz).sum::<usize>(),
    );
    let (enc, dec) = (
        rows.iter().map(|r| r.encode_s).sum::<f64>(),
        rows.iter().map(|r| r.decode_s).sum::<f64>(),
    );
    let summary = format!(
        "{} files with analog channels, {values} values, {raw} raw bytes.\n\
         analog-lossless: {ours} bytes ({:.2}× smaller than raw); xz -9 of the blocks: {} bytes.\n\
         Integer files ({}): analog-lossless {i_ours}, flac -8 {i_flac} ({:.3}× ours), xz -9 {i_xz}.\n\
         Float files ({}): analog-lossless {f_ours}, xz -9 {f_xz} ({:.3}× ours).\n\
         Speed: encode {:.1} M values/s, decode {:.1} M values/s (one core).\n",
        rows.len(),
        raw as f64 / ours as f64,
        opt(xz),
        ints.len(),
        i_flac as f64 / i_ours.max(1) as f64,
        floats.len(),
        f_xz as f64 / f_ours.max(1) as f64,
        values as f64 / enc / 1e6,
        values as f64 / dec / 1e6,
    );
    print!("{summary}");
    let _ = std::fs::create_dir_all(out);
    let file = out.join("analog.md");
    if let Err(e) = std::fs::write(&file, format!("{table}\n{summary}")) {
        eprintln!("{}: {e}", file.display());
        return ExitCode::FAILURE;
    }
    println!("table: {}", file.display());
    ExitCode::SUCCESS
}
