//! `mocapstore verify`, `export` and `import`: an archivist's tools, run against the
//! database directly (the service need not be running).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;

use mocapstore::service::access::Grant;
use mocapstore::service::archive::{self, Imported, ManifestLine};
use mocapstore::service::export;
use mocapstore::service::library::TakeQuery;
use mocapstore::store::{BasisRow, Filter, Store};

/// Which database, and which takes.
#[derive(Args)]
pub struct Selection {
    /// Database: a SQLite file or a postgres:// URL.
    #[arg(long, env = "DATABASE_URL", default_value = "sqlite://mocapstore.db")]
    database_url: String,
    /// Only takes of this library.
    #[arg(long)]
    library: Option<String>,
    /// Only takes with this tag.
    #[arg(long)]
    tag: Option<String>,
}

impl Selection {
    fn filter(&self) -> Filter {
        TakeQuery {
            library: self.library.clone(),
            tag: self.tag.clone(),
            ..TakeQuery::default()
        }
        .filter(&Grant::everything())
    }
}

#[derive(Args)]
pub struct VerifyArgs {
    #[command(flatten)]
    selection: Selection,
}

#[derive(Args)]
pub struct ExportArgs {
    /// Folder to write into (created; without --format it must not hold an export already,
    /// with --format a second run resumes).
    dir: PathBuf,
    #[command(flatten)]
    selection: Selection,
    #[command(flatten)]
    files: super::export::FilesArgs,
}

#[derive(Args)]
pub struct ImportArgs {
    /// A folder written by `mocapstore export`.
    dir: PathBuf,
    /// Database to import into: a SQLite file (created if missing) or a postgres:// URL.
    #[arg(long, env = "DATABASE_URL", default_value = "sqlite://mocapstore.db")]
    database_url: String,
}

/// Open an existing store: verify and export never create an empty database by mistake.
async fn open_existing(url: &str) -> Result<Store, String> {
    if let Some(path) = url
        .strip_prefix("sqlite://")
        .or(url.strip_prefix("sqlite:"))
    {
        let file = path.split('?').next().unwrap_or(path);
        if !Path::new(file).exists() {
            return Err(format!("no database at {file}"));
        }
    }
    Store::open(url).await.map_err(|e| format!("{url}: {e}"))
}

fn runtime(cmd: &str) -> Option<tokio::runtime::Runtime> {
    match tokio::runtime::Runtime::new() {
        Ok(r) => Some(r),
        Err(e) => {
            eprintln!("mocapstore {cmd}: cannot start the runtime: {e}");
            None
        }
    }
}

pub fn verify(args: &VerifyArgs) -> ExitCode {
    let Some(rt) = runtime("verify") else {
        return ExitCode::FAILURE;
    };
    rt.block_on(async {
        let store = match open_existing(&args.selection.database_url).await {
            Ok(s) => s,
            Err(e) => {
                eprintln!("mocapstore verify: {e}");
                return ExitCode::from(2);
            }
        };
        let r = archive::verify(&store, &args.selection.filter(), |_| {}).await;
        store.close().await;
        match r {
            Err(e) => {
                eprintln!("mocapstore verify: {e}");
                ExitCode::from(2)
            }
            Ok(r) => {
                for p in &r.problems {
                    println!("BAD  {} ({}): {}", p.id, p.name, p.what);
                }
                println!(
                    "{} takes, {} chunks, {} frames read and decoded; {} problems{}",
                    r.takes,
                    r.chunks,
                    r.frames,
                    r.problems.len(),
                    if r.without_digest > 0 {
                        format!(
                            " ({} takes stored before decoded digests were kept: decoded, not \
                             compared bit for bit)",
                            r.without_digest
                        )
                    } else {
                        String::new()
                    }
                );
                if r.problems.is_empty() {
                    ExitCode::SUCCESS
                } else {
                    ExitCode::FAILURE
                }
            }
        }
    })
}

pub fn export(args: &ExportArgs) -> ExitCode {
    if args.files.format.is_some() {
        let s = &args.selection;
        return super::export::run(
            &args.dir,
            s.library.as_deref(),
            s.tag.as_deref(),
            &args.files,
        );
    }
    let Some(rt) = runtime("export") else {
        return ExitCode::FAILURE;
    };
    match rt.block_on(export_all(args)) {
        Ok(n) => {
            println!("exported {n} takes to {}", args.dir.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore export: {e}");
            ExitCode::FAILURE
        }
    }
}

async fn export_all(args: &ExportArgs) -> Result<usize, String> {
    let dir = &args.dir;
    let manifest = dir.join("manifest.jsonl");
    if manifest.exists() {
        return Err(format!("{} holds an export already", dir.display()));
    }
    let io = |p: &Path, e: std::io::Error| format!("{}: {e}", p.display());
    std::fs::create_dir_all(dir.join("bases")).map_err(|e| io(dir, e))?;
    std::fs::create_dir_all(dir.join("skeletons")).map_err(|e| io(dir, e))?;
    let store = open_existing(&args.selection.database_url).await?;
    let rows = mocapstore::service::library::all_takes(&store, &args.selection.filter())
        .await
        .map_err(|e| e.to_string())?;
    let mut lines = String::new();
    let n = rows.len();
    let with = archive::ReadWith::default();
    for row in rows {
        let id = row.id.clone();
        let mut t = archive::export_take(&store, &with, row)
            .await
            .map_err(|e| format!("take {id}: {e}"))?;
        let folder = format!(
            "takes/{}",
            if t.take.library.is_empty() {
                "_".to_string()
            } else {
                export::safe(&t.take.library)
            }
        );
        std::fs::create_dir_all(dir.join(&folder)).map_err(|e| io(dir, e))?;
        let stem = format!("{folder}/{}__{}", export::safe(&t.take.name), t.take.id);
        let bitstream = format!("{stem}.mcst");
        let file = format!("{stem}.{}", t.format.name());
        let analog = t.analog.as_ref().map(|_| format!("{stem}.analog.mcst"));
        let parameters = t
            .parameters
            .as_ref()
            .map(|_| format!("{stem}.parameters.zst"));
        let outputs = t.outputs.as_ref().map(|_| format!("{stem}.outputs.mcso"));
        // The open file piece by piece, as it is decoded.
        let path = dir.join(&file);
        let mut out = std::fs::File::create(&path).map_err(|e| io(&path, e))?;
        while let Some(piece) = t.file.next().await.map_err(|e| format!("take {id}: {e}"))? {
            out.write_all(&piece).map_err(|e| io(&path, e))?;
        }
        let mut files = vec![(bitstream.clone(), t.container.to_bytes())];
        if let (Some(rel), Some(c)) = (&analog, &t.analog) {
            files.push((rel.clone(), c.to_bytes()));
        }
        if let (Some(rel), Some(p)) = (&parameters, t.parameters) {
            files.push((rel.clone(), p));
        }
        if let (Some(rel), Some(o)) = (&outputs, t.outputs) {
            files.push((rel.clone(), o));
        }
        for (rel, bytes) in files {
            let p = dir.join(rel);
            std::fs::write(&p, bytes).map_err(|e| io(&p, e))?;
        }
        for b in &t.bases {
            let p = dir.join("bases").join(format!("{}.mcsb", b.id));
            if !p.exists() {
                std::fs::write(&p, &b.payload).map_err(|e| io(&p, e))?;
                let meta = serde_json::to_vec_pretty(b).map_err(|e| e.to_string())?;
                let m = p.with_extension("json");
                std::fs::write(&m, meta).map_err(|e| io(&m, e))?;
            }
        }
        if let Some(rig) = &t.skeleton {
            let p = dir.join("skeletons").join(format!("{}.mcsk", rig.id()));
            if !p.exists() {
                std::fs::write(&p, rig.bytes()).map_err(|e| io(&p, e))?;
            }
        }
        let line = ManifestLine {
            bases: t.bases.iter().map(|b| b.id.clone()).collect(),
            take: t.take,
            bitstream,
            file,
            analog,
            parameters,
            outputs,
        };
        lines += &serde_json::to_string(&line).map_err(|e| e.to_string())?;
        lines.push('\n');
    }
    store.close().await;
    // The manifest last, whole: a folder with one holds a complete export.
    let partial = dir.join("manifest.jsonl.partial");
    std::fs::write(&partial, lines).map_err(|e| io(&partial, e))?;
    std::fs::rename(&partial, &manifest).map_err(|e| io(&manifest, e))?;
    Ok(n)
}

pub fn import(args: &ImportArgs) -> ExitCode {
    let Some(rt) = runtime("import") else {
        return ExitCode::FAILURE;
    };
    match rt.block_on(import_all(args)) {
        Ok((stored, already)) => {
            println!("imported {stored} takes ({already} were stored already)");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mocapstore import: {e}");
            ExitCode::FAILURE
        }
    }
}

async fn import_all(args: &ImportArgs) -> Result<(usize, usize), String> {
    let dir = &args.dir;
    let read = |rel: &str| {
        let p = dir.join(rel);
        std::fs::read(&p).map_err(|e| format!("{}: {e}", p.display()))
    };
    let manifest = String::from_utf8(read("manifest.jsonl")?)
        .map_err(|_| "manifest.jsonl is not UTF-8".to_string())?;
    let store = Store::open(&args.database_url)
        .await
        .map_err(|e| format!("{}: {e}", args.database_url))?;
    let (mut stored, mut already) = (0, 0);
    for (n, text) in manifest
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let line: ManifestLine = serde_json::from_str(text)
            .map_err(|e| format!("manifest.jsonl line {}: {e}", n + 1))?;
        let mut bases = Vec::new();
        for id in &line.bases {
            let meta = read(&format!("bases/{id}.json"))?;
            let mut row: BasisRow =
                serde_json::from_slice(&meta).map_err(|e| format!("bases/{id}.json: {e}"))?;
            row.payload = read(&format!("bases/{id}.mcsb"))?;
            bases.push(row);
        }
        let skeleton = match &line.take.skeleton {
            Some(id) => Some(read(&format!("skeletons/{id}.mcsk"))?),
            None => None,
        };
        let bitstream = read(&line.bitstream)?;
        let beside = archive::Beside {
            analog: line.analog.as_deref().map(read).transpose()?,
            parameters: line.parameters.as_deref().map(read).transpose()?,
            outputs: line.outputs.as_deref().map(read).transpose()?,
        };
        match archive::import_take(&store, &line, bitstream, bases, skeleton, beside).await {
            Ok(Imported::Stored) => stored += 1,
            Ok(Imported::AlreadyStored) => already += 1,
            Err(e) => return Err(format!("{} (take {}): {e}", line.bitstream, line.take.id)),
        }
    }
    store.close().await;
    Ok((stored, already))
}
