//! `mocapstore bench`: compression ratio, errors and speed of codecs on real files.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::Args;

use crate::codec::{self, CodecId, ErrorBound};
use crate::corpus;
use crate::motion::formats::{self, ReadOptions};
use crate::motion::Motion;

#[derive(Args)]
pub struct BenchArgs {
    /// Files or folders (recursively: .bvh .c3d .trc .json .npy); default: $MOCAP_CORPUS.
    paths: Vec<PathBuf>,
    /// Codecs to compare.
    #[arg(long, value_delimiter = ',', default_value = "raw,quant,mdtt")]
    codecs: Vec<CodecId>,
    /// Max-error bounds in mm.
    #[arg(long = "max-error", value_delimiter = ',', default_value = "0.5,1,2,5")]
    max_error: Vec<f64>,
    /// Mean-error bounds in mm.
    #[arg(long = "mean-error", value_delimiter = ',', default_value = "3")]
    mean_error: Vec<f64>,
    /// Folder for table.md, results.csv and rd.png.
    #[arg(long, default_value = "bench-out")]
    out: PathBuf,
    /// Repeat each decode this many times to time it.
    #[arg(long, default_value_t = 5)]
    decode_repeats: usize,
    #[arg(long)]
    unit: Option<String>,
    /// Instead of codecs, compare the entropy coders (adaptive range coder vs zigzag
    /// varints + zstd) on the integer streams `quant` produces at each max bound.
    #[arg(long)]
    entropy: bool,
}

/// One (file, codec, bound) measurement.
#[derive(Debug, Clone)]
pub struct Row {
    pub file: String,
    pub codec: CodecId,
    pub bound: ErrorBound,
    pub frames: usize,
    pub points: usize,
    pub raw_bytes: usize,
    pub stored_bytes: usize,
    pub mean_mm: f64,
    pub rms_mm: f64,
    pub max_mm: f64,
    pub kg_percent: f64,
    pub encode_s: f64,
    pub decode_s: f64,
}

impl Row {
    fn ratio(&self) -> f64 {
        self.raw_bytes as f64 / self.stored_bytes as f64
    }
    fn bits_per_frame(&self) -> f64 {
        self.stored_bytes as f64 * 8.0 / self.frames as f64
    }
}

/// Mocap files under `paths`, recursively, sorted.
pub(super) fn collect_files(paths: &[PathBuf]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack: Vec<PathBuf> = paths.to_vec();
    while let Some(p) = stack.pop() {
        if p.is_dir() {
            if let Ok(rd) = std::fs::read_dir(&p) {
                stack.extend(rd.flatten().map(|e| e.path()));
            }
        } else if p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
            matches!(
                e.to_ascii_lowercase().as_str(),
                "bvh" | "c3d" | "trc" | "json" | "npy"
            )
        }) {
            out.push(p);
        }
    }
    out.sort();
    out
}

/// Measure one take with one codec at one bound.
pub fn measure(
    name: &str,
    motion: &Motion,
    codec: CodecId,
    bound: ErrorBound,
    repeats: usize,
) -> Result<Row, String> {
    let t0 = Instant::now();
    let enc = codec::encode(motion, codec, bound).map_err(|e| e.to_string())?;
    let encode_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    for _ in 0..repeats.max(1) {
        std::hint::black_box(codec::decode_all(&enc.container).map_err(|e| e.to_string())?);
    }
    let decode_s = t1.elapsed().as_secs_f64() / repeats.max(1) as f64;
    Ok(Row {
        file: name.to_string(),
        codec,
        bound,
        frames: motion.frame_count(),
        points: motion.point_count(),
        raw_bytes: motion.frame_count() * motion.point_count() * 12,
        stored_bytes: enc.stored_bytes,
        mean_mm: enc.stats.mean_mm,
        rms_mm: enc.stats.rms_mm,
        max_mm: enc.stats.max_mm,
        kg_percent: enc.stats.kg_percent,
        encode_s,
        decode_s,
    })
}

fn bound_label(b: ErrorBound) -> String {
    match b {
        ErrorBound::MaxMm(v) => format!("max {v}"),
        ErrorBound::MeanMm(v) => format!("mean {v}"),
    }
}

/// Totals per (codec, bound) over all files: sizes add, errors weight by samples.
pub fn totals(rows: &[Row]) -> Vec<Row> {
    let mut keys: Vec<(CodecId, String)> = Vec::new();
    for r in rows {
        let k = (r.codec, bound_label(r.bound));
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .map(|(codec, label)| {
            let sel: Vec<&Row> = rows
                .iter()
                .filter(|r| r.codec == codec && bound_label(r.bound) == label)
                .collect();
            let samples: f64 = sel.iter().map(|r| (r.frames * r.points) as f64).sum();
            let wavg = |f: &dyn Fn(&Row) -> f64| {
                sel.iter()
                    .map(|r| f(r) * (r.frames * r.points) as f64)
                    .sum::<f64>()
                    / samples
            };
            Row {
                file: format!("TOTAL ({} takes)", sel.len()),
                codec,
                bound: sel[0].bound,
                frames: sel.iter().map(|r| r.frames).sum(),
                points: 0,
                raw_bytes: sel.iter().map(|r| r.raw_bytes).sum(),
                stored_bytes: sel.iter().map(|r| r.stored_bytes).sum(),
                mean_mm: wavg(&|r| r.mean_mm),
                rms_mm: (wavg(&|r| r.rms_mm * r.rms_mm)).sqrt(),
                max_mm: sel.iter().map(|r| r.max_mm).fold(0.0, f64::max),
                kg_percent: wavg(&|r| r.kg_percent),
                encode_s: sel.iter().map(|r| r.encode_s).sum(),
                decode_s: sel.iter().map(|r| r.decode_s).sum(),
            }
        })
        .collect()
}

pub fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "| file | codec | bound (mm) | frames | CR | bits/frame | mean mm | RMS mm | max mm | d% | enc fps | dec fps |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} | {:.0} | {:.3} | {:.3} | {:.3} | {:.3} | {:.0} | {:.0} |",
            r.file,
            r.codec,
            bound_label(r.bound),
            r.frames,
            r.ratio(),
            r.bits_per_frame(),
            r.mean_mm,
            r.rms_mm,
            r.max_mm,
            r.kg_percent,
            r.frames as f64 / r.encode_s,
            r.frames as f64 / r.decode_s
        );
    }
    s
}

fn csv(rows: &[Row]) -> String {
    let mut s = String::from("file,codec,bound_kind,bound_mm,frames,points,raw_bytes,stored_bytes,ratio,bits_per_frame,mean_mm,rms_mm,max_mm,kg_percent,encode_fps,decode_fps\n");
    for r in rows {
        let (kind, v) = match r.bound {
            ErrorBound::MaxMm(v) => ("max", v),
            ErrorBound::MeanMm(v) => ("mean", v),
        };
        let _ = writeln!(
            s,
            "{},{},{kind},{v},{},{},{},{},{:.4},{:.2},{:.5},{:.5},{:.5},{:.5},{:.1},{:.1}",
            r.file.replace(',', ";"),
            r.codec,
            r.frames,
            r.points,
            r.raw_bytes,
            r.stored_bytes,
            r.ratio(),
            r.bits_per_frame(),
            r.mean_mm,
            r.rms_mm,
            r.max_mm,
            r.kg_percent,
            r.frames as f64 / r.encode_s,
            r.frames as f64 / r.decode_s
        );
    }
    s
}

pub fn run(args: &BenchArgs) -> ExitCode {
    let paths = if args.paths.is_empty() {
        vec![corpus::root()]
    } else {
        args.paths.clone()
    };
    let files = collect_files(&paths);
    if files.is_empty() {
        eprintln!("mocapstore bench: no mocap files under {paths:?}");
        return ExitCode::FAILURE;
    }
    let unit = match &args.unit {
        Some(u) => match crate::motion::units::parse_unit(u) {
            Ok(m) => Some(m),
            Err(e) => {
                eprintln!("mocapstore bench: {e}");
                return ExitCode::from(2);
            }
        },
        None => None,
    };
    let mut bounds = Vec::new();
    for &b in &args.max_error {
        bounds.push(ErrorBound::new_max(b));
    }
    for &b in &args.mean_error {
        bounds.push(ErrorBound::new_mean(b));
    }
    let bounds: Vec<ErrorBound> = match bounds.into_iter().collect() {
        Ok(b) => b,
        Err(e) => {
            eprintln!("mocapstore bench: {e}");
            return ExitCode::from(2);
        }
    };
    let opts = ReadOptions {
        unit,
        ..Default::default()
    };
    if args.entropy {
        return entropy_comparison(&files, &args.max_error, &opts, &args.out);
    }
    let mut rows = Vec::new();
    let mut failures = 0;
    for path in &files {
        let name = short_name(path);
        let motion = match std::fs::read(path)
            .map_err(|e| e.to_string())
            .and_then(|b| formats::read(&b, &opts).map_err(|e| e.to_string()))
        {
            Ok(l)
                if l.motion.point_count() > 0
                    && l.motion.frame_count() > 0
                    && l.motion.gap_fraction() < 1.0 =>
            {
                l.motion
            }
            Ok(_) => {
                eprintln!("{name}: skipped: no point samples");
                continue;
            }
            Err(e) => {
                eprintln!("{name}: skipped: {e}");
                continue;
            }
        };
        for &codec in &args.codecs {
            for &bound in &bounds {
                if codec == CodecId::Raw && bound != bounds[0] {
                    continue; // lossless: one row is enough
                }
                match measure(&name, &motion, codec, bound, args.decode_repeats) {
                    Ok(r) => {
                        eprintln!(
                            "{name} {codec} {}: CR {:.1}, max {:.3} mm",
                            bound_label(bound),
                            r.ratio(),
                            r.max_mm
                        );
                        rows.push(r);
                    }
                    Err(e) => {
                        failures += 1;
                        eprintln!("{name} {codec} {}: FAILED: {e}", bound_label(bound));
                    }
                }
            }
        }
    }
    let sums = totals(&rows);
    let mut all = rows.clone();
    all.extend(sums.iter().cloned());
    let table = markdown(&all);
    println!("{table}");
    if let Err(e) = write_outputs(&args.out, &table, &csv(&all))
        .and_then(|()| super::plot::rate_distortion(&sums, &args.out.join("rd.png")))
    {
        eprintln!("mocapstore bench: {e}");
        return ExitCode::FAILURE;
    }
    eprintln!("wrote {}/table.md, results.csv, rd.png", args.out.display());
    if failures > 0 {
        eprintln!("{failures} encodes failed");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

fn short_name(p: &Path) -> String {
    let s = p.display().to_string();
    let root = corpus::root().display().to_string();
    s.strip_prefix(&root)
        .map(|r| r.trim_start_matches('/').to_string())
        .unwrap_or(s)
}

fn write_outputs(dir: &Path, table: &str, csv: &str) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    std::fs::write(dir.join("table.md"), table).map_err(|e| e.to_string())?;
    std::fs::write(dir.join("results.csv"), csv).map_err(|e| e.to_string())?;
    Ok(())
}

/// Bytes and encode time of each entropy coder over the same integers.
#[derive(Default, Clone, Copy)]
struct CoderTotals {
    bytes: usize,
    seconds: f64,
}

/// Range coder vs zstd on `quant`'s per-chunk integer streams (and, for zstd's benefit, on
/// whole takes as one stream).
fn entropy_comparison(
    files: &[PathBuf],
    bounds: &[f64],
    opts: &ReadOptions,
    out: &Path,
) -> ExitCode {
    use crate::codec::entropy::zstd_varint;
    use crate::codec::{default_chunk_frames, quant, Target};
    let names = [
        "range coder (per chunk)",
        "zstd-3 (per chunk)",
        "zstd-19 (per chunk)",
        "zstd-19 (whole take)",
    ];
    let mut table = String::from("| max bound mm | integers | coder | bytes | bits/integer | encode MB/s of integers |\n|---:|---:|---|---:|---:|---:|\n");
    for &b in bounds {
        let mut totals = [CoderTotals::default(); 4];
        let mut count = 0usize;
        for path in files {
            let Ok(m) = std::fs::read(path)
                .map_err(|e| e.to_string())
                .and_then(|bytes| formats::read(&bytes, opts).map_err(|e| e.to_string()))
                .map(|l| l.motion)
            else {
                continue;
            };
            if m.point_count() == 0 || m.frame_count() == 0 || m.gap_fraction() >= 1.0 {
                continue;
            }
            let filled = crate::codec::gaps::fill(m.positions(), m.point_count());
            let target = Target::Max(b / m.unit.to_mm());
            let Ok(step) = quant::step_for(&filled, None, target) else {
                continue;
            };
            let q: Vec<i32> = filled
                .iter()
                .map(|&x| crate::codec::measure::quantise(f64::from(x) / step))
                .collect();
            let w = m.point_count() * 3;
            let per = default_chunk_frames(m.fps);
            let mut whole = Vec::with_capacity(q.len());
            for f0 in (0..m.frame_count()).step_by(per) {
                let n = per.min(m.frame_count() - f0);
                let block = &q[f0 * w..(f0 + n) * w];
                let ints = quant::prediction_residuals(block, n, w, 2);
                count += ints.len();
                let timed = |t: &mut CoderTotals, f: &dyn Fn() -> usize| {
                    let t0 = Instant::now();
                    t.bytes += f();
                    t.seconds += t0.elapsed().as_secs_f64();
                };
                timed(&mut totals[0], &|| {
                    quant::encode_block(block, n, w, 2).len()
                });
                timed(&mut totals[1], &|| zstd_varint::encode(&ints, 3).len());
                timed(&mut totals[2], &|| zstd_varint::encode(&ints, 19).len());
                whole.extend(ints);
            }
            let t0 = Instant::now();
            totals[3].bytes += zstd_varint::encode(&whole, 19).len();
            totals[3].seconds += t0.elapsed().as_secs_f64();
        }
        for (name, t) in names.iter().zip(totals) {
            let _ = writeln!(
                table,
                "| {b} | {count} | {name} | {} | {:.3} | {:.1} |",
                t.bytes,
                t.bytes as f64 * 8.0 / count.max(1) as f64,
                count as f64 * 4.0 / 1e6 / t.seconds.max(1e-9)
            );
        }
    }
    println!("{table}");
    if let Err(e) =
        std::fs::create_dir_all(out).and_then(|_| std::fs::write(out.join("entropy.md"), &table))
    {
        eprintln!("mocapstore bench: {}: {e}", out.display());
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
