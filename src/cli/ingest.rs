//! `mocapstore ingest DIR|FILE… --server URL`: upload a folder of takes with a progress
//! bar and a few uploads in flight, then a summary; exit non-zero if any motion file failed.
//!
//! A dataset folder as it is published holds more than motion: label files beside each
//! take (Bandai Namco's `{"content": 7, "style": 0}`), readmes, scripts. Files are told by
//! content ([`formats::is_motion`]), not by extension: what is not motion is skipped and
//! counted once in the summary, never uploaded and never a failure.
//!
//! Labels ([`mocapstore::labels`]) come from three places, each over the one before: the
//! file's name read by `--labels-from-name`, a sidecar beside it with its name (`.json`,
//! `.yaml`, `.yml`: an object of key → value, nested objects as `outer.inner`), and
//! `--labels` for every file.

use std::collections::{HashMap, HashSet};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::Value;
use tokio::sync::Semaphore;

use mocapstore::labels::{Labels, NamePattern};
use mocapstore::motion::formats;

#[derive(Args)]
pub struct IngestArgs {
    /// Files or folders (searched recursively; motion is told by content, the rest skipped).
    #[arg(required = true)]
    paths: Vec<PathBuf>,
    /// The service to upload to.
    #[arg(long, env = "MOCAP_SERVER", default_value = "http://127.0.0.1:8080")]
    server: String,
    /// API token of a server that needs one (`mocapstore token create`).
    #[arg(long, env = "MOCAP_TOKEN", hide_env_values = true)]
    token: Option<String>,
    #[arg(long)]
    library: Option<String>,
    /// Comma-separated tags for every file.
    #[arg(long)]
    tags: Option<String>,
    /// Labels for every file: `key:value,…` (or a JSON object); over a sidecar's and the
    /// name's.
    #[arg(long)]
    labels: Option<String>,
    /// Label each take by its file name: `{dataset}_{content}_{style}_{n}` reads
    /// `dataset-1_walk_happy_001` as dataset, content, style and n (`{}` matches without
    /// labelling). A name that does not fit gets no labels from it, and is counted.
    #[arg(long = "labels-from-name", value_name = "PATTERN")]
    labels_from_name: Option<String>,
    /// Leave label files beside the takes unread (they are read by default).
    #[arg(long = "no-sidecar-labels")]
    no_sidecar_labels: bool,
    /// No decoded sample farther than this, mm (default 1; 10× the mean when only a mean
    /// is given: the default cap).
    #[arg(long = "max-error-mm")]
    max_error_mm: Option<f64>,
    /// Mean error at most this, mm; with --max-error-mm, both hold.
    #[arg(long = "mean-error-mm")]
    mean_error_mm: Option<f64>,
    /// auto, or a codec id.
    #[arg(long)]
    codec: Option<String>,
    /// frame, clip, sequence or any.
    #[arg(long)]
    latency: Option<String>,
    /// For skeleton takes: animation (the default: only codecs that keep the channel values,
    /// so the take comes back as BVH) or positions (position codecs compete too).
    #[arg(long)]
    keep: Option<String>,
    /// For `spca`: the torso points of the files' marker set, by name: origin, left
    /// shoulder, right shoulder (e.g. `C7,LSHO,RSHO`); found by name when not given.
    #[arg(long)]
    torso: Option<String>,
    /// Unit of the files (mm, cm, m, in, cmu or metres per unit).
    #[arg(long)]
    unit: Option<String>,
    /// Uploads in flight at once.
    #[arg(long, default_value_t = 4)]
    concurrency: usize,
    /// Store files whose data contradicts their header (cut short, values beyond any
    /// physical scale) with a warning, instead of having them refused.
    #[arg(long)]
    lenient: bool,
}

struct Outcome {
    file: String,
    result: Result<Value, String>,
}

/// Bytes read of a file to tell whether it is motion (all of a JSON file, which must be
/// parsed to tell a take from a label file).
const SNIFF_BYTES: u64 = 64 << 10;

/// The files under the paths given, sorted into those to upload and those skipped.
#[derive(Default)]
struct Gathered {
    motion: Vec<PathBuf>,
    /// Files beside a take with its name (`walk_001.json` beside `walk_001.bvh`): labels,
    /// by the take's path without its extension.
    sidecars: HashMap<PathBuf, Vec<PathBuf>>,
    /// Anything else that is not motion, and why.
    other: Vec<(PathBuf, String)>,
}

/// Whether the file at `path` is motion, by its content; Err: it cannot be read.
fn sniff(path: &Path) -> std::io::Result<bool> {
    let mut head = Vec::new();
    std::fs::File::open(path)?
        .take(SNIFF_BYTES)
        .read_to_end(&mut head)?;
    if matches!(formats::detect(&head), Ok(formats::Format::Json)) {
        return Ok(formats::is_motion(&std::fs::read(path)?));
    }
    Ok(formats::is_motion(&head))
}

/// Every file under `paths` (folders recursively; hidden files and folders left out),
/// sorted by what it is.
fn gather(paths: &[PathBuf]) -> Gathered {
    let mut files = Vec::new();
    let mut stack: Vec<PathBuf> = paths.to_vec();
    while let Some(p) = stack.pop() {
        let hidden = p
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'));
        if p.is_dir() {
            if let Ok(rd) = std::fs::read_dir(&p) {
                stack.extend(rd.flatten().map(|e| e.path()));
            }
        } else if !hidden || paths.contains(&p) {
            files.push(p);
        }
    }
    files.sort();
    let mut g = Gathered::default();
    let mut rest = Vec::new();
    for f in files {
        // A file named as motion is uploaded whatever it holds: if it is none, that is a
        // failure the server names (an empty .trc), not a file to pass over.
        let named = f
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| MOTION_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
        match sniff(&f) {
            Ok(true) => g.motion.push(f),
            _ if named => g.motion.push(f),
            Ok(false) => rest.push((f, "not motion".to_string())),
            Err(e) => rest.push((f, format!("cannot be read: {e}"))),
        }
    }
    let takes: HashSet<PathBuf> = g.motion.iter().map(|p| p.with_extension("")).collect();
    for (f, why) in rest {
        let stem = f.with_extension("");
        if why == "not motion" && takes.contains(&stem) {
            g.sidecars.entry(stem).or_default().push(f);
        } else {
            g.other.push((f, why));
        }
    }
    g
}

/// Extensions only motion files have (`.json` may be labels or anything else).
const MOTION_EXTENSIONS: &[&str] = &["bvh", "c3d", "trc", "npy"];

/// Skipped files named in the summary; the rest are counted.
const SKIPPED_LISTED: usize = 20;

/// The largest label file read: a dataset's sidecar is a few lines.
const SIDECAR_BYTES: u64 = 1 << 20;

/// A sidecar's labels: a JSON or YAML object of key → value. Err: the file and why.
fn sidecar_labels(path: &Path) -> Result<Labels, String> {
    let named = |e: String| format!("label file {}: {e}", path.display());
    let len = std::fs::metadata(path)
        .map_err(|e| named(e.to_string()))?
        .len();
    if len > SIDECAR_BYTES {
        return Err(named(format!(
            "{len} bytes, more than a label file's {SIDECAR_BYTES}"
        )));
    }
    let text = std::fs::read_to_string(path).map_err(|e| named(e.to_string()))?;
    let yaml = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "yaml" | "yml"));
    let value: Value = if yaml {
        serde_yaml_ng::from_str(&text).map_err(|e| named(e.to_string()))?
    } else {
        serde_json::from_str(&text).map_err(|e| named(e.to_string()))?
    };
    Labels::from_json(&value).map_err(named)
}

/// What labels a file: the parts of `--labels-from-name`, `--labels` and the sidecars.
struct Labelling {
    pattern: Option<NamePattern>,
    given: Labels,
    sidecars: HashMap<PathBuf, Vec<PathBuf>>,
    /// Files whose names did not fit the pattern, and takes labelled by a sidecar.
    unfit: Vec<PathBuf>,
    from_sidecar: usize,
}

impl Labelling {
    fn new(args: &IngestArgs, sidecars: HashMap<PathBuf, Vec<PathBuf>>) -> Result<Self, String> {
        Ok(Labelling {
            pattern: args
                .labels_from_name
                .as_deref()
                .map(NamePattern::parse)
                .transpose()?,
            given: args
                .labels
                .as_deref()
                .map(Labels::parse)
                .transpose()
                .map_err(|e| format!("--labels: {e}"))?
                .unwrap_or_default(),
            sidecars: if args.no_sidecar_labels {
                HashMap::new()
            } else {
                sidecars
            },
            unfit: Vec::new(),
            from_sidecar: 0,
        })
    }

    /// The labels of the take at `path` (its name's, its sidecars' over them, the given
    /// ones over those), as the JSON the server reads; `None` when it has none.
    fn of(&mut self, path: &Path) -> Result<Option<String>, String> {
        let mut labels = Labels::new();
        if let Some(p) = &self.pattern {
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
            match stem.as_deref().and_then(|s| p.labels(s)) {
                Some(l) => labels = l,
                None => self.unfit.push(path.to_path_buf()),
            }
        }
        if let Some(files) = self.sidecars.get(&path.with_extension("")) {
            for f in files {
                labels.merge(&sidecar_labels(f)?)?;
            }
            self.from_sidecar += 1;
        }
        labels.merge(&self.given)?;
        Ok((!labels.is_empty()).then(|| serde_json::to_string(&labels).expect("labels serialise")))
    }
}

pub fn run(args: &IngestArgs) -> ExitCode {
    let gathered = gather(&args.paths);
    let files = gathered.motion;
    let sidecar_files: usize = gathered.sidecars.values().map(Vec::len).sum();
    if files.is_empty() {
        eprintln!(
            "mocapstore ingest: no motion files under {:?} ({} other files)",
            args.paths,
            sidecar_files + gathered.other.len()
        );
        return ExitCode::FAILURE;
    }
    let mut labelling = match Labelling::new(args, gathered.sidecars) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("mocapstore ingest: {e}");
            return ExitCode::FAILURE;
        }
    };
    // A take whose labels cannot be read is a failure named with its label file, and not
    // uploaded: stored without them, it would pass for an unlabelled take.
    let mut outcomes = Vec::new();
    let mut jobs = Vec::new();
    for f in files {
        match labelling.of(&f) {
            Ok(labels) => jobs.push((f, labels)),
            Err(e) => outcomes.push(Outcome {
                file: f.display().to_string(),
                result: Err(e),
            }),
        }
    }
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("mocapstore ingest: {e}");
            return ExitCode::FAILURE;
        }
    };
    let client = match super::token::client(args.token.as_deref()) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("mocapstore ingest: {e}");
            return ExitCode::FAILURE;
        }
    };
    outcomes.extend(runtime.block_on(upload_all(args, &client, jobs)));
    let failed: Vec<&Outcome> = outcomes.iter().filter(|o| o.result.is_err()).collect();
    println!(
        "{:<48} {:<8} {:>8} {:>9} {:>9}",
        "file", "codec", "frames", "ratio", "max mm"
    );
    for o in &outcomes {
        if let Ok(v) = &o.result {
            println!(
                "{:<48} {:<8} {:>8} {:>9.1} {:>9.3}",
                o.file,
                v["codec"].as_str().unwrap_or("?"),
                v["frames"].as_u64().unwrap_or(0),
                v["ratio"].as_f64().unwrap_or(0.0),
                v["max_mm"].as_f64().unwrap_or(0.0)
            );
        }
    }
    println!(
        "{} stored, {} failed, {} skipped ({} beside takes with their names, {} other files \
         that are not motion)",
        outcomes.len() - failed.len(),
        failed.len(),
        sidecar_files + gathered.other.len(),
        sidecar_files,
        gathered.other.len()
    );
    if labelling.from_sidecar > 0 {
        println!(
            "{} takes labelled from the files beside them",
            labelling.from_sidecar
        );
    }
    if let Some(first) = labelling.unfit.first() {
        println!(
            "{} names do not fit --labels-from-name (the first: {}): no labels from their names",
            labelling.unfit.len(),
            first.display()
        );
    }
    for (f, why) in gathered.other.iter().take(SKIPPED_LISTED) {
        println!("skipped {}: {why}", f.display());
    }
    if gathered.other.len() > SKIPPED_LISTED {
        println!(
            "… and {} more skipped",
            gathered.other.len() - SKIPPED_LISTED
        );
    }
    for o in &failed {
        if let Err(e) = &o.result {
            eprintln!("{}: {e}", o.file);
        }
    }
    if failed.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

/// Upload each file with its labels (JSON), a few at a time.
async fn upload_all(
    args: &IngestArgs,
    client: &reqwest::Client,
    files: Vec<(PathBuf, Option<String>)>,
) -> Vec<Outcome> {
    let bar = ProgressBar::new(files.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed} {wide_msg}")
            .expect("valid template"),
    );
    let slots = Arc::new(Semaphore::new(args.concurrency.max(1)));
    let mut fixed: Vec<(&str, String)> = Vec::new();
    for (k, v) in [
        ("library", &args.library),
        ("tags", &args.tags),
        ("codec", &args.codec),
        ("latency", &args.latency),
        ("keep", &args.keep),
        ("torso", &args.torso),
        ("unit", &args.unit),
    ] {
        if let Some(v) = v {
            fixed.push((k, v.clone()));
        }
    }
    if let Some(v) = args.max_error_mm {
        fixed.push(("max_error_mm", v.to_string()));
    }
    if let Some(v) = args.mean_error_mm {
        fixed.push(("mean_error_mm", v.to_string()));
    }
    if args.lenient {
        fixed.push(("lenient", "true".into()));
    }
    let url = format!("{}/v1/takes", args.server.trim_end_matches('/'));
    let mut tasks = Vec::new();
    for (path, labels) in files {
        let (client, slots, bar, url) = (client.clone(), slots.clone(), bar.clone(), url.clone());
        let mut query = fixed.clone();
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        query.push(("name", name));
        if let Some(l) = labels {
            query.push(("labels", l));
        }
        tasks.push(tokio::spawn(async move {
            let _slot = slots.acquire().await.expect("semaphore open");
            let file = path.display().to_string();
            bar.set_message(file.clone());
            let result = upload(&client, &url, &query, &path).await;
            bar.inc(1);
            Outcome { file, result }
        }));
    }
    let mut out = Vec::new();
    for t in tasks {
        if let Ok(o) = t.await {
            out.push(o);
        }
    }
    bar.finish_and_clear();
    out
}

async fn upload(
    client: &reqwest::Client,
    url: &str,
    query: &[(&str, String)],
    path: &PathBuf,
) -> Result<Value, String> {
    let body = tokio::fs::read(path).await.map_err(|e| e.to_string())?;
    let resp = client
        .post(url)
        .query(query)
        .body(body)
        .send()
        .await
        .map_err(|e| format!("cannot reach the server: {e}"))?;
    let status = resp.status();
    let v: Value = resp.json().await.unwrap_or(Value::Null);
    if status.is_success() {
        Ok(v)
    } else {
        Err(format!(
            "{status}: {}",
            v["error"]["message"].as_str().unwrap_or("no error message")
        ))
    }
}
