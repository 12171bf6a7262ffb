//! `mocapstore bench`: compression ratio, errors and speed of codecs on real files.

mod analog;
mod euler;
mod lossless;
mod plot;
mod search;
mod search_speed;

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use clap::Args;

use mocapstore::codec::mdtt::{self, ClipMode};
use mocapstore::codec::spca::{self, encode::Options as SpcaOptions};
use mocapstore::codec::{self, Basis, BasisKind, CodecId, ErrorBound};
use mocapstore::corpus;
use mocapstore::motion::formats::{self, ReadOptions};
use mocapstore::motion::Motion;

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
    /// Mean-error bounds in mm, each with the default max cap (10× the mean) that a request
    /// stating only a mean gets.
    #[arg(long = "mean-error", value_delimiter = ',', default_value = "3")]
    mean_error: Vec<f64>,
    /// Folder for table.md, results.csv, rd.png (rate–distortion) and speed.png.
    #[arg(long, default_value = "bench-out")]
    out: PathBuf,
    /// Repeat each decode (and each decoder's construction) this many times to time it.
    #[arg(long, default_value_t = 5)]
    decode_repeats: usize,
    #[arg(long)]
    unit: Option<String>,
    /// Codecs with a shared basis train it per layout on every N-th take (in name order)
    /// and every codec is then measured on the other takes only.
    #[arg(long, default_value_t = 2)]
    train_every: usize,
    /// Clip lengths (seconds) to measure `lsdt-clip` at; each is its own row.
    #[arg(long, value_delimiter = ',', default_value = "1")]
    clip_seconds: Vec<f64>,
    /// Report only takes at most this long (seconds), e.g. 5 for the short-take comparison.
    #[arg(long)]
    max_seconds: Option<f64>,
    /// Intra periods (seconds; `inf` for none) to measure `lsdt-frame` at.
    #[arg(long, value_delimiter = ',', default_value = "1")]
    intra_seconds: Vec<f64>,
    /// How `mdtt` cuts clips, each its own row: `equal` (one length, the codec's default)
    /// and `adaptive` (at PPCA segment boundaries).
    #[arg(long, value_delimiter = ',', default_value = "equal")]
    mdtt_clips: Vec<String>,
    /// The parts of `spca` to measure, each its own row (the paper's Table 3): `pca` (one
    /// PCA model for the take, every frame a key), `segments` (a model per segment, every
    /// frame a key), `full` (segments and key frames: the codec).
    #[arg(long, value_delimiter = ',', default_value = "full")]
    spca_parts: Vec<String>,
    /// Instead of codecs, compare the entropy coders (adaptive range coder vs zigzag
    /// varints + zstd) on the integer streams `quant` produces at each max bound.
    #[arg(long)]
    entropy: bool,
    /// Instead of codecs, compare `bvh-lossless` with xz -9e, zstd -19 and gzip -9 on the
    /// BVH files, file by file.
    #[arg(long)]
    lossless: bool,
    /// Instead of codecs, compare `analog-lossless` with flac -8 (per channel, integer
    /// files) and xz -9 of the analog block, on the C3D files, file by file.
    #[arg(long)]
    analog: bool,
    /// Instead of codecs, how well motion features find motion by motion: precision@5 of
    /// the content label of takes named `<dataset>_<content>_<style>_<n>` (Bandai Namco's),
    /// whole takes and 1 s windows as queries, beside a mean-pose baseline.
    #[arg(long)]
    search: bool,
    /// With --search: also what search costs through the store, on an archive of the files
    /// ingested again under other names until it holds this many frames (e.g. 300000):
    /// latency p50/p99, the features' share of the database, ingest slowdown.
    #[arg(long, requires = "search")]
    search_frames: Option<u64>,
    /// With --search-frames: searches timed.
    #[arg(long, default_value_t = 400)]
    search_queries: usize,
    /// Instead of sizes, how `rot` and `pga` give a BVH's Euler channels back at the first
    /// max bound: jumps over 90° between frames against the source's, and the largest
    /// channel difference, file by file.
    #[arg(long)]
    euler: bool,
}

/// One (file, codec, bound) measurement.
#[derive(Debug, Clone)]
pub struct Row {
    pub file: String,
    pub codec: CodecId,
    /// The codec and any setting measured apart (e.g. `lsdt-clip L=0.5s`).
    pub label: String,
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
    /// Decoding the whole take with a decoder built beforehand, as the service's read
    /// path does (it caches a decoder per take).
    pub decode_s: f64,
    /// Building the take's decoder (header, basis, entropy tables), paid once per take;
    /// in totals, the mean per take.
    pub setup_s: f64,
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

/// A codec and the setting it is measured at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Variant {
    /// As per-take choice runs it.
    Default(CodecId),
    /// `lsdt-clip` with clips of this many seconds.
    Clip(f64),
    /// `lsdt-frame` with an intra frame every this many seconds (infinite: none).
    Intra(f64),
    /// `spca` with some parts of the method left out.
    Spca(SpcaOptions),
    /// `mdtt` with clips cut this way.
    Mdtt(ClipMode),
}

impl Variant {
    fn codec(self) -> CodecId {
        match self {
            Variant::Default(c) => c,
            Variant::Clip(_) => CodecId::LsdtClip,
            Variant::Intra(_) => CodecId::LsdtFrame,
            Variant::Spca(_) => CodecId::Spca,
            Variant::Mdtt(_) => CodecId::Mdtt,
        }
    }

    fn label(self) -> String {
        match self {
            Variant::Default(c) => c.to_string(),
            Variant::Clip(s) => format!("lsdt-clip L={s}s"),
            Variant::Intra(s) if s.is_infinite() => "lsdt-frame no intra".to_string(),
            Variant::Intra(s) => format!("lsdt-frame I={s}s"),
            Variant::Spca(o) => match (o.segmented, o.keyframes) {
                (true, true) => "spca".to_string(),
                (true, false) => "spca segments, no key frames".to_string(),
                (false, false) => "spca one PCA, no key frames".to_string(),
                (false, true) => "spca one PCA, key frames".to_string(),
            },
            Variant::Mdtt(ClipMode::Equal) => "mdtt".to_string(),
            Variant::Mdtt(ClipMode::Adaptive) => "mdtt adaptive clips".to_string(),
        }
    }

    fn encode(
        self,
        motion: &Motion,
        bound: ErrorBound,
        shared: Option<&Arc<Basis>>,
    ) -> codec::Result<codec::Encoded> {
        use mocapstore::codec::lsdt::{clip, frame};
        let frames_of = |s: f64| {
            if s.is_infinite() {
                motion.frame_count()
            } else {
                ((s * motion.fps).round() as usize).max(1)
            }
        };
        use codec::EncodeOptions as O;
        let options = match self {
            Variant::Default(_) => O::with_basis(shared),
            Variant::Clip(s) => O::with_encoder(shared, move |i, t| {
                clip::encode_with_clip(i, t, frames_of(s))
            }),
            Variant::Intra(s) => O::with_encoder(shared, move |i, t| {
                frame::encode_with_period(i, t, frames_of(s))
            }),
            Variant::Spca(o) => O::with_encoder(shared, move |i, t| spca::encode_with(i, t, o)),
            Variant::Mdtt(mode) => {
                O::with_encoder(shared, move |i, t| mdtt::encode_clips(i, t, mode))
            }
        };
        codec::encode(motion, self.codec(), bound, options)
    }
}

/// Measure one take with one codec at one bound.
pub fn measure(
    name: &str,
    motion: &Motion,
    variant: Variant,
    bound: ErrorBound,
    shared: Option<&Arc<Basis>>,
    repeats: usize,
) -> Result<Row, String> {
    let t0 = Instant::now();
    let enc = variant
        .encode(motion, bound, shared)
        .map_err(|e| e.to_string())?;
    let encode_s = t0.elapsed().as_secs_f64();
    let header = &enc.container.header;
    let shared = codec::Shared {
        basis: shared.cloned(),
        rig: enc.rig.clone(),
    };
    let repeats = repeats.max(1);
    let t1 = Instant::now();
    for _ in 0..repeats {
        std::hint::black_box(
            codec::Reader::new(header.clone(), shared.clone()).map_err(|e| e.to_string())?,
        );
    }
    let setup_s = t1.elapsed().as_secs_f64() / repeats as f64;
    let reader = codec::Reader::new(header.clone(), shared.clone()).map_err(|e| e.to_string())?;
    let chunks = codec::Stored::new(0, enc.container.chunks.iter().map(Vec::as_slice));
    let t2 = Instant::now();
    for _ in 0..repeats {
        std::hint::black_box(reader.read_all(&chunks).map_err(|e| e.to_string())?);
    }
    let decode_s = t2.elapsed().as_secs_f64() / repeats as f64;
    Ok(Row {
        file: name.to_string(),
        codec: variant.codec(),
        label: variant.label(),
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
        setup_s,
    })
}

fn bound_label(b: ErrorBound) -> String {
    match b.mean_mm() {
        None => format!("max {}", b.max_mm()),
        Some(m) if b.max_is_default() => format!("mean {m}"),
        Some(m) => format!("mean {m}, max {}", b.max_mm()),
    }
}

/// Totals per (codec, bound) over all files: sizes add, errors weight by samples.
pub fn totals(rows: &[Row]) -> Vec<Row> {
    let mut keys: Vec<(String, String)> = Vec::new();
    for r in rows {
        let k = (r.label.clone(), bound_label(r.bound));
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .map(|(variant, label)| {
            let sel: Vec<&Row> = rows
                .iter()
                .filter(|r| r.label == variant && bound_label(r.bound) == label)
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
                codec: sel[0].codec,
                label: variant,
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
                setup_s: sel.iter().map(|r| r.setup_s).sum::<f64>() / sel.len() as f64,
            }
        })
        .collect()
}

pub fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "| file | codec | bound (mm) | frames | CR | bits/frame | mean mm | RMS mm | max mm | d% | enc fps | dec fps | dec setup µs |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} | {:.0} | {:.3} | {:.3} | {:.3} | {:.3} | {:.0} | {:.0} | {:.0} |",
            r.file,
            r.label,
            bound_label(r.bound),
            r.frames,
            r.ratio(),
            r.bits_per_frame(),
            r.mean_mm,
            r.rms_mm,
            r.max_mm,
            r.kg_percent,
            r.frames as f64 / r.encode_s,
            r.frames as f64 / r.decode_s,
            r.setup_s * 1e6
        );
    }
    s
}

fn csv(rows: &[Row]) -> String {
    let mut s = String::from("file,codec,max_bound_mm,mean_bound_mm,frames,points,raw_bytes,stored_bytes,ratio,bits_per_frame,mean_mm,rms_mm,max_mm,kg_percent,encode_fps,decode_fps,decode_setup_us\n");
    for r in rows {
        let (max, mean) = (
            r.bound.max_mm(),
            r.bound.mean_mm().map_or(String::new(), |m| m.to_string()),
        );
        let _ = writeln!(
            s,
            "{},{},{max},{mean},{},{},{},{},{:.4},{:.2},{:.5},{:.5},{:.5},{:.5},{:.1},{:.1},{:.1}",
            r.file.replace(',', ";"),
            r.label,
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
            r.frames as f64 / r.decode_s,
            r.setup_s * 1e6
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
        Some(u) => match mocapstore::motion::units::parse_unit(u) {
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
        bounds.push(ErrorBound::from_request(Some(b), None));
    }
    for &b in &args.mean_error {
        // The default cap, as a request with only a mean gets.
        bounds.push(ErrorBound::from_request(None, Some(b)));
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
    if args.lossless {
        return lossless::run(&files, &args.out);
    }
    if args.analog {
        return analog::run(&files, &args.out);
    }
    if args.search {
        let measured = search::run(&files);
        let Some(frames) = args.search_frames else {
            return measured;
        };
        let runtime = match tokio::runtime::Runtime::new() {
            Ok(r) => r,
            Err(e) => {
                eprintln!("mocapstore bench --search: {e}");
                return ExitCode::FAILURE;
            }
        };
        return match runtime.block_on(search_speed::run(&files, frames, args.search_queries)) {
            Ok(()) => measured,
            Err(e) => {
                eprintln!("mocapstore bench --search-frames: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if args.euler {
        let bound = args.max_error.first().copied().unwrap_or(1.0);
        return euler::run(&files, bound, &args.out);
    }
    let mut takes = Vec::new();
    for path in &files {
        let name = short_name(path);
        match std::fs::read(path)
            .map_err(|e| e.to_string())
            .and_then(|b| formats::read(&b, &opts).map_err(|e| e.to_string()))
        {
            Ok(l)
                if l.motion.point_count() > 0
                    && l.motion.frame_count() > 0
                    && l.motion.gap_fraction() < 1.0 =>
            {
                takes.push((name, l.motion))
            }
            Ok(_) => eprintln!("{name}: skipped: no point samples"),
            Err(e) => eprintln!("{name}: skipped: {e}"),
        }
    }
    let mut variants = Vec::new();
    for &c in &args.codecs {
        match c {
            CodecId::LsdtClip => {
                variants.extend(args.clip_seconds.iter().map(|&s| Variant::Clip(s)))
            }
            CodecId::LsdtFrame => {
                variants.extend(args.intra_seconds.iter().map(|&s| Variant::Intra(s)))
            }
            CodecId::Mdtt => {
                for mode in &args.mdtt_clips {
                    variants.push(Variant::Mdtt(match mode.as_str() {
                        "equal" => ClipMode::Equal,
                        "adaptive" => ClipMode::Adaptive,
                        other => {
                            eprintln!(
                                "mocapstore bench: --mdtt-clips takes equal, adaptive; not {other:?}"
                            );
                            return ExitCode::from(2);
                        }
                    }));
                }
            }
            CodecId::Spca => {
                for part in &args.spca_parts {
                    let (segmented, keyframes) = match part.as_str() {
                        "pca" => (false, false),
                        "segments" => (true, false),
                        "full" => (true, true),
                        other => {
                            eprintln!(
                                "mocapstore bench: --spca-parts takes pca, segments, full; not {other:?}"
                            );
                            return ExitCode::from(2);
                        }
                    };
                    variants.push(Variant::Spca(SpcaOptions {
                        segmented,
                        keyframes,
                    }));
                }
            }
            c => variants.push(Variant::Default(c)),
        }
    }
    let shared_needed = args
        .codecs
        .iter()
        .any(|&c| codec::codec(c).is_ok_and(|k| k.basis_kind().is_some()));
    let kinds: Vec<BasisKind> = args
        .codecs
        .iter()
        .filter_map(|&c| codec::codec(c).ok().and_then(|k| k.basis_kind()))
        .collect();
    let (test, bases) = if shared_needed {
        match split_and_train(takes, args.train_every, &kinds) {
            Ok(x) => x,
            Err(e) => {
                eprintln!("mocapstore bench: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        (takes, Default::default())
    };
    let mut rows = Vec::new();
    let mut failures = 0;
    let short_enough = |m: &Motion| args.max_seconds.is_none_or(|s| m.duration_s() <= s);
    for (name, motion) in test.iter().filter(|(_, m)| short_enough(m)) {
        let layout = motion.layout_signature().to_hex();
        for &variant in &variants {
            let shared = bases
                .get(&layout)
                .and_then(|bs| mocapstore::service::choose::basis_for(variant.codec(), bs));
            let shared = shared.as_ref();
            for &bound in &bounds {
                if variant.codec() == CodecId::Raw && bound != bounds[0] {
                    continue; // lossless: one row is enough
                }
                let label = variant.label();
                match measure(name, motion, variant, bound, shared, args.decode_repeats) {
                    Ok(r) => {
                        eprintln!(
                            "{name} {label} {}: CR {:.1}, max {:.3} mm",
                            bound_label(bound),
                            r.ratio(),
                            r.max_mm
                        );
                        rows.push(r);
                    }
                    Err(e) => {
                        failures += 1;
                        eprintln!("{name} {label} {}: FAILED: {e}", bound_label(bound));
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
        .and_then(|()| plot::rate_distortion(&sums, &args.out.join("rd.png")))
        .and_then(|()| plot::speed(&sums, &args.out.join("speed.png")))
    {
        eprintln!("mocapstore bench: {e}");
        return ExitCode::FAILURE;
    }
    eprintln!(
        "wrote {}/table.md, results.csv, rd.png, speed.png",
        args.out.display()
    );
    if failures > 0 {
        eprintln!("{failures} encodes failed");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

/// Split takes per layout into training (every `every`-th in name order) and test, and
/// train an LSDT basis per layout on its training takes. Layouts with a single take are
/// left out: nothing could be held apart.
#[allow(clippy::type_complexity)]
fn split_and_train(
    takes: Vec<(String, Motion)>,
    every: usize,
    kinds: &[BasisKind],
) -> Result<(Vec<(String, Motion)>, HashMap<String, Vec<Arc<Basis>>>), String> {
    use mocapstore::codec::lsdt::train::{train_basis, TrainOptions};
    let every = every.max(2);
    let mut groups: HashMap<String, Vec<(String, Motion)>> = HashMap::new();
    for t in takes {
        groups
            .entry(t.1.layout_signature().to_hex())
            .or_default()
            .push(t);
    }
    let mut test = Vec::new();
    let mut bases = HashMap::new();
    let mut layouts: Vec<_> = groups.into_iter().collect();
    layouts.sort_by(|a, b| a.1[0].0.cmp(&b.1[0].0));
    for (layout, mut group) in layouts {
        if group.len() < 2 {
            eprintln!("{}: skipped: the only take of its layout", group[0].0);
            continue;
        }
        group.sort_by(|a, b| a.0.cmp(&b.0));
        let (train, held): (Vec<_>, Vec<_>) = group
            .into_iter()
            .enumerate()
            .partition(|(i, _)| i % every == 0);
        let mm: Vec<Vec<f32>> = train
            .iter()
            .map(|(_, (_, m))| {
                let k = m.unit.to_mm() as f32;
                m.positions().iter().map(|v| v * k).collect()
            })
            .collect();
        let slices: Vec<&[f32]> = mm.iter().map(Vec::as_slice).collect();
        let t0 = Instant::now();
        let points = train[0].1 .1.point_count();
        let mut trained = Vec::new();
        if kinds.contains(&BasisKind::Lsdt) {
            let t = match train_basis(&slices, points, &TrainOptions::default(), 50_000) {
                Ok(t) => t,
                Err(e) => {
                    eprintln!("layout {}: skipped: lsdt training: {e}", &layout[..8]);
                    continue;
                }
            };
            eprintln!(
                "layout {}: trained lsdt on {} takes ({} frames sampled) in {:.1} s; objective x {:.4e} → {:.4e}, {} iterations",
                &layout[..8],
                train.len(),
                t.samples,
                t0.elapsed().as_secs_f64(),
                t.runs[0].objective[0],
                t.runs[0].objective.last().unwrap_or(&0.0),
                t.runs[0].objective.len() - 1
            );
            trained.push(Arc::new(t.basis));
        }
        if kinds.contains(&BasisKind::MdttSet) {
            use mocapstore::codec::mdtt::database::{train_set, SetOptions};
            let t1 = Instant::now();
            let filled: Vec<(Vec<f32>, Vec<bool>)> = train
                .iter()
                .map(|(_, (_, m))| {
                    let p = m.positions();
                    (codec::gaps::fill(p, m.point_count()), codec::gaps::mask(p))
                })
                .collect();
            let inputs: Vec<codec::Input<'_>> = train
                .iter()
                .zip(&filled)
                .map(|((_, (_, m)), (data, valid))| codec::Input {
                    data,
                    valid: Some(valid),
                    frames: m.frame_count(),
                    points,
                    fps: m.fps,
                    shared: None,
                    skeleton: None,
                    names: &[],
                    torso: None,
                })
                .collect();
            let targets: Vec<codec::Target> = train
                .iter()
                .map(|(_, (_, m))| codec::Target::max(1.0 / m.unit.to_mm()))
                .collect();
            let t = match train_set(&inputs, &targets, &SetOptions::default()) {
                Ok(t) => t,
                Err(e) => {
                    eprintln!("layout {}: skipped: mdtt-set training: {e}", &layout[..8]);
                    continue;
                }
            };
            eprintln!(
                "layout {}: trained mdtt-set on {} takes ({} clips, rank {}) in {:.1} s; K chosen {} by total bytes (K, takes, bases): {:?}",
                &layout[..8],
                train.len(),
                t.clips,
                t.rank,
                t1.elapsed().as_secs_f64(),
                t.basis.matrices().len(),
                t.sizes
            );
            trained.push(Arc::new(t.basis));
        }
        bases.insert(layout, trained);
        test.extend(held.into_iter().map(|(_, t)| t));
    }
    Ok((test, bases))
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
    use mocapstore::codec::entropy::zstd_varint;
    use mocapstore::codec::{default_chunk_frames, quant, Target};
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
            let filled = mocapstore::codec::gaps::fill(m.positions(), m.point_count());
            let target = Target::max(b / m.unit.to_mm());
            let Ok(step) = quant::step_for(&filled, None, target) else {
                continue;
            };
            let q: Vec<i32> = filled
                .iter()
                .map(|&x| mocapstore::codec::measure::quantise(f64::from(x) / step))
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
