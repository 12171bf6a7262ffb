//! The files an ingest is given, and their bytes: files on disk, folders searched
//! recursively, and ZIP archives read entry by entry as if they were folders (a dataset as
//! it is downloaded: `mocapstore ingest data.zip`). Each is told by its content, not its
//! extension, and sorted into takes, label files beside them and the rest.

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use mocapstore::motion::formats;

/// Bytes read of a file to tell whether it is motion (all of a JSON file, which must be
/// parsed to tell a take from a label file).
const SNIFF_BYTES: u64 = 64 << 10;

/// Extensions only motion files have (`.json` may be labels or anything else).
const MOTION_EXTENSIONS: &[&str] = &["bvh", "c3d", "trc", "npy", "fbx", "glb", "gltf"];

/// The largest entry of a ZIP read: what a server takes as one upload by default
/// ([`mocapstore::limits::Limits::upload_bytes`]). An entry that says it is larger, or
/// turns out larger as it is inflated, is refused before it is held.
fn entry_limit() -> u64 {
    mocapstore::limits::Limits::default().upload_bytes
}

/// Where the files of an ingest are: an entry of a ZIP has a path of its own, the
/// archive's path joined with its name in it (`data.zip/data/walk_001.bvh`), read from
/// the archive (each opened once); any other path is read from disk.
#[derive(Default)]
pub struct Sources {
    entries: HashMap<PathBuf, (PathBuf, String)>,
    open: Mutex<HashMap<PathBuf, zip::ZipArchive<File>>>,
}

impl Sources {
    /// At most `limit` bytes of the file at `path` (all of it if `limit` is `None`): Err if
    /// it cannot be read, or it is a ZIP entry larger than [`entry_limit`].
    pub fn read(&self, path: &Path, limit: Option<u64>) -> std::io::Result<Vec<u8>> {
        let mut out = Vec::new();
        let Some((archive, name)) = self.entries.get(path) else {
            let f = File::open(path)?;
            match limit {
                Some(n) => f.take(n).read_to_end(&mut out)?,
                None => (&f).read_to_end(&mut out)?,
            };
            return Ok(out);
        };
        let mut open = self.open.lock().expect("zip lock");
        if !open.contains_key(archive) {
            let z = zip::ZipArchive::new(File::open(archive)?).map_err(std::io::Error::other)?;
            open.insert(archive.clone(), z);
        }
        let z = open.get_mut(archive).expect("opened above");
        let entry = z.by_name(name).map_err(std::io::Error::other)?;
        let most = entry_limit();
        if limit.is_none() && entry.size() > most {
            return Err(std::io::Error::other(format!(
                "{} bytes inflated, more than an upload's {most}",
                entry.size()
            )));
        }
        let want = limit.unwrap_or(most);
        entry.take(want + 1).read_to_end(&mut out)?;
        if limit.is_none() && out.len() as u64 > most {
            return Err(std::io::Error::other(format!(
                "more than an upload's {most} bytes inflated (its header said less)"
            )));
        }
        out.truncate(want as usize);
        Ok(out)
    }

    /// Whether the file at `path` is motion, by its content; Err: it cannot be read.
    fn sniff(&self, path: &Path) -> std::io::Result<bool> {
        let head = self.read(path, Some(SNIFF_BYTES))?;
        if matches!(formats::detect(&head), Ok(formats::Format::Json)) {
            return Ok(formats::is_motion(&self.read(path, None)?));
        }
        Ok(formats::is_motion(&head))
    }

    /// The entries of the ZIP at `archive` as paths of their own (folders, hidden entries
    /// and macOS's `__MACOSX` shadows left out). Err: it is no ZIP we can read.
    fn list(&mut self, archive: &Path) -> Result<Vec<PathBuf>, String> {
        let z = File::open(archive)
            .map_err(|e| e.to_string())
            .and_then(|f| zip::ZipArchive::new(f).map_err(|e| e.to_string()))?;
        let mut out = Vec::new();
        for name in z.file_names() {
            let name = name.map_err(|e| e.to_string())?;
            let parts: Vec<&str> = name.split('/').filter(|p| !p.is_empty()).collect();
            let skip = name.ends_with('/')
                || parts.is_empty()
                || parts
                    .iter()
                    .any(|p| p.starts_with('.') || *p == "__MACOSX" || *p == "..");
            if skip {
                continue;
            }
            let path = parts.iter().fold(archive.to_path_buf(), |p, s| p.join(s));
            self.entries
                .insert(path.clone(), (archive.to_path_buf(), name.to_string()));
            out.push(path);
        }
        self.open
            .lock()
            .expect("zip lock")
            .insert(archive.to_path_buf(), z);
        Ok(out)
    }
}

/// The files under the paths given, sorted into those to upload and those skipped.
#[derive(Default)]
pub struct Gathered {
    pub motion: Vec<PathBuf>,
    /// Files beside a take with its name (`walk_001.json` beside `walk_001.bvh`): labels,
    /// by the take's path without its extension.
    pub sidecars: HashMap<PathBuf, Vec<PathBuf>>,
    /// Anything else that is not motion, and why.
    pub other: Vec<(PathBuf, String)>,
    /// Where each file's bytes are.
    pub sources: Sources,
}

/// Whether `path` names a ZIP archive (by its first bytes, whatever its name).
fn is_zip(path: &Path) -> bool {
    let mut head = [0u8; 4];
    File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|()| head == *b"PK\x03\x04" || head == *b"PK\x05\x06")
}

/// Every file under `paths` (folders recursively, ZIP archives entry by entry; hidden
/// files and folders left out), sorted by what it is.
pub fn gather(paths: &[PathBuf]) -> Gathered {
    let mut g = Gathered::default();
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
        } else if hidden && !paths.contains(&p) {
        } else if is_zip(&p) {
            match g.sources.list(&p) {
                Ok(entries) => files.extend(entries),
                Err(e) => g.other.push((p, format!("a ZIP that cannot be read: {e}"))),
            }
        } else {
            files.push(p);
        }
    }
    files.sort();
    let mut rest = Vec::new();
    for f in files {
        // A file named as motion is uploaded whatever it holds: if it is none, that is a
        // failure the server names (an empty .trc), not a file to pass over.
        let named = f
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| MOTION_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
        match g.sources.sniff(&f) {
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
