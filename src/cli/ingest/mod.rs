//! `mocapstore ingest DIR|FILE… --server URL`: upload a folder of takes with a progress
//! bar and a few uploads in flight, then a summary; exit non-zero if any motion file failed.
//!
//! A dataset folder as it is published holds more than motion: label files beside each
//! take (Bandai Namco's `{"content": 7, "style": 0}`), readmes, scripts. Files are told by
//! content ([`formats::is_motion`]), not by extension: what is not motion is skipped and
//! counted once in the summary, never uploaded and never a failure.
//!
//! A ZIP of such a folder is read the same way, entry by entry, never unpacked to disk
//! ([`files`]). Labels come from the file's name, the label files beside it and
//! `--labels` ([`labelling`]).

mod files;
mod labelling;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::Value;
use tokio::sync::Semaphore;

use files::{gather, Sources};
use labelling::Labelling;

#[derive(Args)]
pub struct IngestArgs {
    /// Files, folders (searched recursively) or ZIP archives of them; motion is told by
    /// content, the rest skipped.
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

/// Skipped files named in the summary; the rest are counted.
const SKIPPED_LISTED: usize = 20;

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
        match labelling.of(&gathered.sources, &f) {
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
    let sources = Arc::new(gathered.sources);
    outcomes.extend(runtime.block_on(upload_all(args, &client, sources, jobs)));
    let failed: Vec<&Outcome> = outcomes.iter().filter(|o| o.result.is_err()).collect();
    println!(
        "{:<48} {:<8} {:>8} {:>9} {:>9}",
        "file", "codec", "frames", "ratio", "max mm"
    );
    let row = |file: &str, v: &Value| {
        println!(
            "{:<48} {:<8} {:>8} {:>9.1} {:>9.3}",
            file,
            v["codec"].as_str().unwrap_or("?"),
            v["frames"].as_u64().unwrap_or(0),
            v["ratio"].as_f64().unwrap_or(0.0),
            v["max_mm"].as_f64().unwrap_or(0.0)
        )
    };
    // A file of several animations is a take for each: a row for each, named by its take.
    let mut several = 0;
    for o in &outcomes {
        if let Ok(v) = &o.result {
            row(&o.file, v);
            for more in v["more"].as_array().into_iter().flatten() {
                row(
                    &format!("  + {}", more["name"].as_str().unwrap_or("?")),
                    more,
                );
                several += 1;
            }
        }
    }
    if several > 0 {
        println!("{several} more takes from files of several animations (rows with +)");
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
    sources: Arc<Sources>,
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
        let sources = sources.clone();
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
            let result = upload(&client, &url, &query, &sources, &path).await;
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
    sources: &Arc<Sources>,
    path: &Path,
) -> Result<Value, String> {
    let (sources, p) = (sources.clone(), path.to_path_buf());
    let body = tokio::task::spawn_blocking(move || sources.read(&p, None))
        .await
        .map_err(|e| e.to_string())?
        .map_err(|e| e.to_string())?;
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
