//! `mocapstore export DIR --format glb --library L`: a library as files people open, from a
//! running service — what `GET /v1/export` streams as a ZIP, written file by file into a
//! folder with a progress bar, and resumable.
//!
//! Names and the manifest are the service's own ([`export::plan`], [`Entry::csv_line`]), so
//! the folder holds what the ZIP would. Each file is fetched through the one read path
//! (`/v1/takes/{id}/frames` with the format and transforms), written beside its place
//! as `.partial` and renamed when whole. A journal (`.mocapstore-export.jsonl`: the options,
//! then a line per file written) lets a second run skip every file whose size and BLAKE3 are
//! what was written; a file changed or cut short since is fetched again. `manifest.csv` is
//! written last.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use tokio::sync::Semaphore;

use mocapstore::motion::formats::Format;
use mocapstore::service::export::{self, Entry, MANIFEST};
use mocapstore::service::take::Take;

/// The journal of an export folder.
const JOURNAL: &str = ".mocapstore-export.jsonl";

/// Retries of a fetch the server refused for now (503, its answer budget full).
const BUSY_RETRIES: u32 = 30;

#[derive(Args, Clone)]
pub struct FilesArgs {
    /// Export files for use in this format (glb, gltf, fbx, bvh, c3d, trc, csv, json, npy, f32)
    /// from a running service, instead of the archive from the database.
    #[arg(long)]
    pub format: Option<String>,
    /// The service to export from (with --format).
    #[arg(long, env = "MOCAP_SERVER", default_value = "http://127.0.0.1:8080")]
    server: String,
    /// API token of a server that needs one (`mocapstore token create`).
    #[arg(long, env = "MOCAP_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Resample every take to this frame rate.
    #[arg(long)]
    fps: Option<f64>,
    /// Root motion: keep, in-place or extract.
    #[arg(long)]
    root: Option<String>,
    /// Up axis of positions: y or z.
    #[arg(long)]
    up: Option<String>,
    /// Unit of positions (mm, cm, m, in, …).
    #[arg(long)]
    unit: Option<String>,
    /// Put every take on this skeleton (bvh, glb, gltf, fbx): a standard rig (mixamo,
    /// smpl), a stored skeleton's id or take:ID.
    #[arg(long)]
    skeleton: Option<String>,
    /// With --skeleton: lock holds each foot still while the source's stands.
    #[arg(long)]
    feet: Option<String>,
    /// Files fetched at once.
    #[arg(long, default_value_t = 2)]
    concurrency: usize,
}

/// What the journal's first line holds: an export resumed with other options would mix
/// files of two kinds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Options {
    format: String,
    library: Option<String>,
    tag: Option<String>,
    fps: Option<f64>,
    root: Option<String>,
    up: Option<String>,
    unit: Option<String>,
    #[serde(default)]
    skeleton: Option<String>,
    #[serde(default)]
    feet: Option<String>,
}

pub fn run(dir: &Path, library: Option<&str>, tag: Option<&str>, args: &FilesArgs) -> ExitCode {
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("mocapstore export: {e}");
            return ExitCode::FAILURE;
        }
    };
    match runtime.block_on(export_files(dir, library, tag, args)) {
        Ok((written, kept, skipped)) => {
            println!(
                "{written} files written, {kept} already there, {skipped} takes skipped \
                 (manifest.csv says why) in {}",
                dir.display()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore export: {e}");
            ExitCode::FAILURE
        }
    }
}

async fn export_files(
    dir: &Path,
    library: Option<&str>,
    tag: Option<&str>,
    args: &FilesArgs,
) -> Result<(usize, usize, usize), String> {
    let format: Format = args
        .format
        .as_deref()
        .unwrap_or("json")
        .parse()
        .map_err(|e| format!("--format: {e}"))?;
    // Refused here as the service would refuse them for every take.
    let transform = mocapstore::motion::transform::Options {
        fps: args.fps,
        root: match &args.root {
            Some(r) => r.parse().map_err(|e| format!("--root: {e}"))?,
            None => Default::default(),
        },
        up: match &args.up {
            Some(u) => Some(u.parse().map_err(|e| format!("--up: {e}"))?),
            None => None,
        },
        metres_per_unit: match &args.unit {
            Some(u) => {
                Some(mocapstore::motion::units::parse_unit(u).map_err(|e| format!("--unit: {e}"))?)
            }
            None => None,
        },
    };
    mocapstore::service::answer::transform_for(format, transform).map_err(|e| e.to_string())?;
    if args.skeleton.is_some() {
        mocapstore::service::retarget::check_format(format)
            .map_err(|e| format!("--skeleton: {e}"))?;
    }
    let options = Options {
        format: format.name().to_string(),
        library: library.map(str::to_string),
        tag: tag.map(str::to_string),
        fps: args.fps,
        root: args.root.clone(),
        up: args.up.clone(),
        unit: args.unit.clone(),
        skeleton: args.skeleton.clone(),
        feet: args.feet.clone(),
    };
    let io = |p: &Path, e: std::io::Error| format!("{}: {e}", p.display());
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let (resumed, done) = read_journal(dir, &options)?;
    let client = super::token::client(args.token.as_deref())?;
    let server = args.server.trim_end_matches('/').to_string();
    let takes = list(&client, &server, library, tag).await?;
    let mut entries = export::plan(&takes, format);
    drop(takes);

    let mut journal = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(dir.join(JOURNAL))
        .map_err(|e| io(&dir.join(JOURNAL), e))?;
    // A line an interrupted run cut short ends here, not glued to the next.
    if resumed && !journal_ends_whole(&dir.join(JOURNAL)) {
        writeln!(journal).map_err(|e| io(&dir.join(JOURNAL), e))?;
    }
    if !resumed {
        writeln!(journal, "{}", json(&options)).map_err(|e| io(&dir.join(JOURNAL), e))?;
    }

    let bar = ProgressBar::new(entries.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed} {wide_msg}")
            .expect("valid template"),
    );
    let mut query: Vec<(&str, String)> = vec![("format", options.format.clone())];
    for (k, v) in [
        ("root", &args.root),
        ("up", &args.up),
        ("unit", &args.unit),
        ("skeleton", &args.skeleton),
        ("feet", &args.feet),
    ] {
        if let Some(v) = v {
            query.push((k, v.clone()));
        }
    }
    if let Some(fps) = args.fps {
        query.push(("fps", fps.to_string()));
    }
    let slots = Arc::new(Semaphore::new(args.concurrency.max(1)));
    let mut tasks = Vec::new();
    let mut kept = 0;
    for (i, entry) in entries.iter().enumerate() {
        if let Some(d) = done.get(&entry.id) {
            if d.file == entry.file && unchanged(&dir.join(&d.file), d).await {
                kept += 1;
                bar.inc(1);
                continue;
            }
        }
        let (client, slots, bar) = (client.clone(), slots.clone(), bar.clone());
        let url = format!("{server}/v1/takes/{}/frames", entry.id);
        let (query, path) = (query.clone(), dir.join(&entry.file));
        tasks.push((
            i,
            tokio::spawn(async move {
                let _slot = slots.acquire().await.expect("semaphore open");
                let r = fetch(&client, &url, &query, &path).await;
                bar.inc(1);
                r
            }),
        ));
    }
    let (mut written, mut skipped, mut failed) = (0, 0, 0);
    for (i, task) in tasks {
        let got = task
            .await
            .map_err(|e| format!("a fetch failed: {e}"))?
            .map_err(|e| format!("{}: {e}", entries[i].file))?;
        let e = &mut entries[i];
        match got {
            Fetched::File {
                bytes,
                blake3,
                frames,
                fps,
                metres_per_unit,
                points,
            } => {
                (e.bytes, e.blake3) = (Some(bytes), Some(blake3));
                (e.frames, e.fps) = (frames.unwrap_or(e.frames), fps.unwrap_or(e.fps));
                e.metres_per_unit = metres_per_unit.unwrap_or(e.metres_per_unit);
                e.points = mocapstore::service::answer::points_written(
                    std::mem::take(&mut e.points),
                    points,
                );
                writeln!(journal, "{}", json(&*e)).map_err(|err| io(&dir.join(JOURNAL), err))?;
                written += 1;
            }
            Fetched::Skipped(why) => {
                e.skipped = Some(why);
                skipped += 1;
            }
            Fetched::Failed(why) => {
                eprintln!("mocapstore export: {}: {why}", e.file);
                e.skipped = Some(why);
                failed += 1;
            }
        }
    }
    bar.finish_and_clear();
    // Files kept from an earlier run are listed as that run wrote them.
    for e in &mut entries {
        if let Some(d) = done.get(&e.id) {
            if e.bytes.is_none() && e.skipped.is_none() {
                *e = d.clone();
            }
        }
    }
    let manifest = export::manifest(&entries);
    let partial = dir.join(format!("{MANIFEST}.partial"));
    std::fs::write(&partial, manifest).map_err(|e| io(&partial, e))?;
    std::fs::rename(&partial, dir.join(MANIFEST)).map_err(|e| io(&dir.join(MANIFEST), e))?;
    if failed > 0 {
        return Err(format!(
            "the server failed to write {failed} takes (listed above and in manifest.csv); \
             run again to retry them"
        ));
    }
    Ok((written, kept, skipped))
}

/// Whether a journal ends with a whole line.
fn journal_ends_whole(path: &Path) -> bool {
    std::fs::read(path).is_ok_and(|b| b.last().is_none_or(|&c| c == b'\n'))
}

fn json<T: Serialize>(v: &T) -> String {
    serde_json::to_string(v).expect("plain records serialize")
}

/// Whether an earlier run left a journal in `dir`, and the files it wrote, by take id;
/// refused when it ran with other options.
fn read_journal(dir: &Path, options: &Options) -> Result<(bool, HashMap<String, Entry>), String> {
    let path = dir.join(JOURNAL);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if dir.join(MANIFEST).exists() || dir.join("manifest.jsonl").exists() {
                return Err(format!(
                    "{} holds an export this command did not write; use an empty folder",
                    dir.display()
                ));
            }
            return Ok((false, HashMap::new()));
        }
        Err(e) => return Err(format!("{}: {e}", path.display())),
    };
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let Some(first) = lines.next() else {
        return Ok((false, HashMap::new()));
    };
    let was: Options =
        serde_json::from_str(first).map_err(|e| format!("{}: line 1: {e}", path.display()))?;
    if was != *options {
        return Err(format!(
            "{} holds an export with other options ({}); use another folder",
            dir.display(),
            first
        ));
    }
    let mut done = HashMap::new();
    for (n, line) in lines.enumerate() {
        // A line cut short by an interrupted run is the last; what it names is fetched again.
        match serde_json::from_str::<Entry>(line) {
            Ok(e) => {
                done.insert(e.id.clone(), e);
            }
            Err(_) => eprintln!(
                "mocapstore export: {} line {} does not parse; its file is fetched again",
                path.display(),
                n + 2
            ),
        }
    }
    Ok((true, done))
}

/// Whether a file is still what the journal says was written: same size, same BLAKE3.
async fn unchanged(path: &Path, entry: &Entry) -> bool {
    let (Some(bytes), Some(digest)) = (entry.bytes, entry.blake3.clone()) else {
        return false;
    };
    let path = path.to_path_buf();
    tokio::task::spawn_blocking(move || {
        let size_ok = std::fs::metadata(&path).is_ok_and(|m| m.len() == bytes);
        let mut hasher = blake3::Hasher::new();
        size_ok
            && std::fs::File::open(&path)
                .and_then(|mut f| std::io::copy(&mut f, &mut hasher))
                .is_ok()
            && hasher.finalize().to_hex().to_string() == digest
    })
    .await
    .unwrap_or(false)
}

/// Every take of the selection, oldest first (the order the service names them in).
async fn list(
    client: &reqwest::Client,
    server: &str,
    library: Option<&str>,
    tag: Option<&str>,
) -> Result<Vec<Take>, String> {
    #[derive(Deserialize)]
    struct Page {
        items: Vec<Take>,
        next_cursor: Option<String>,
    }
    let mut out = Vec::new();
    let mut cursor: Option<String> = None;
    loop {
        let mut q: Vec<(&str, String)> = vec![
            ("sort", "created".into()),
            ("order", "asc".into()),
            ("limit", "500".into()),
        ];
        for (k, v) in [("library", library), ("tag", tag)] {
            if let Some(v) = v {
                q.push((k, v.to_string()));
            }
        }
        if let Some(c) = &cursor {
            q.push(("cursor", c.clone()));
        }
        let r = client
            .get(format!("{server}/v1/takes"))
            .query(&q)
            .send()
            .await
            .map_err(|e| format!("cannot reach the server: {e}"))?;
        let status = r.status();
        let body = r.bytes().await.map_err(|e| e.to_string())?;
        if !status.is_success() {
            return Err(format!(
                "listing the takes: {status}: {}",
                super::token::error_message(&body)
            ));
        }
        let page: Page =
            serde_json::from_slice(&body).map_err(|e| format!("listing the takes: {e}"))?;
        out.extend(page.items);
        match page.next_cursor {
            Some(c) => cursor = Some(c),
            None => return Ok(out),
        }
    }
}

enum Fetched {
    File {
        bytes: u64,
        blake3: String,
        frames: Option<usize>,
        fps: Option<f64>,
        metres_per_unit: Option<f64>,
        /// Points per frame (`None` for a file of joints, BVH).
        points: Option<usize>,
    },
    /// The take cannot be written in this format (the service said why).
    Skipped(String),
    /// The server failed to write it.
    Failed(String),
}

/// Fetch one take's file to `path` (through `path.partial`, renamed when whole).
async fn fetch(
    client: &reqwest::Client,
    url: &str,
    query: &[(&str, String)],
    path: &PathBuf,
) -> Result<Fetched, String> {
    let mut tries = 0;
    let mut r = loop {
        let r = client
            .get(url)
            .query(query)
            .send()
            .await
            .map_err(|e| format!("cannot reach the server: {e}"))?;
        if r.status() == reqwest::StatusCode::SERVICE_UNAVAILABLE && tries < BUSY_RETRIES {
            tries += 1;
            let wait = r
                .headers()
                .get(reqwest::header::RETRY_AFTER)
                .and_then(|v| v.to_str().ok()?.parse().ok())
                .unwrap_or(2);
            tokio::time::sleep(Duration::from_secs(wait)).await;
            continue;
        }
        break r;
    };
    let status = r.status();
    if !status.is_success() {
        let body = r.bytes().await.map_err(|e| e.to_string())?;
        let why = super::token::error_message(&body);
        return match status.as_u16() {
            // The token does not reach it, or the server is not ready: nothing will do.
            401 | 403 | 503 => Err(format!("{status}: {why}")),
            // This take cannot be written so (the format cannot hold it, it was deleted
            // since it was listed), or the server could not read it (a damaged take; the
            // server's log says more): skipped, as the service's ZIP skips it.
            400..=499 => Ok(Fetched::Skipped(why)),
            _ => Ok(Fetched::Failed(format!("{status}: {why}"))),
        };
    }
    let header = |name: &str| {
        r.headers()
            .get(name)
            .and_then(|v| v.to_str().ok())
            .map(str::to_string)
    };
    let frames = header("x-frames").and_then(|v| v.parse().ok());
    let fps = header("x-fps").and_then(|v| v.parse().ok());
    let metres_per_unit = header("x-metres-per-unit").and_then(|v| v.parse().ok());
    let points = header("x-points").and_then(|v| v.parse().ok());
    let io = |p: &Path, e: std::io::Error| format!("{}: {e}", p.display());
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
    }
    let partial = path.with_extension(format!(
        "{}.partial",
        path.extension().and_then(|e| e.to_str()).unwrap_or("")
    ));
    let mut file = std::fs::File::create(&partial).map_err(|e| io(&partial, e))?;
    let mut hasher = blake3::Hasher::new();
    let mut bytes = 0u64;
    while let Some(chunk) = r
        .chunk()
        .await
        .map_err(|e| format!("the answer was cut short: {e}"))?
    {
        hasher.update(&chunk);
        bytes += chunk.len() as u64;
        file.write_all(&chunk).map_err(|e| io(&partial, e))?;
    }
    file.sync_all().map_err(|e| io(&partial, e))?;
    drop(file);
    std::fs::rename(&partial, path).map_err(|e| io(path, e))?;
    Ok(Fetched::File {
        bytes,
        blake3: hasher.finalize().to_hex().to_string(),
        frames,
        fps,
        metres_per_unit,
        points,
    })
}
