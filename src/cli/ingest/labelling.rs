//! A take's labels as `mocapstore ingest` gives them ([`mocapstore::labels`]), each over
//! the one before: its file name read by `--labels-from-name`, the label files beside it
//! with its name (`.json`, `.yaml`, `.yml`: an object of key → value, nested objects as
//! `outer.inner`), and `--labels` for every file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::files::Sources;
use super::IngestArgs;
use mocapstore::labels::{Labels, NamePattern};

/// The largest label file read: a dataset's sidecar is a few lines.
const SIDECAR_BYTES: u64 = 1 << 20;

/// A sidecar's labels: a JSON or YAML object of key → value. Err: the file and why.
fn sidecar_labels(sources: &Sources, path: &Path) -> Result<Labels, String> {
    let named = |e: String| format!("label file {}: {e}", path.display());
    let bytes = sources
        .read(path, Some(SIDECAR_BYTES + 1))
        .map_err(|e| named(e.to_string()))?;
    if bytes.len() as u64 > SIDECAR_BYTES {
        return Err(named(format!(
            "more than a label file's {SIDECAR_BYTES} bytes"
        )));
    }
    let text = String::from_utf8(bytes).map_err(|e| named(e.to_string()))?;
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
pub struct Labelling {
    pattern: Option<NamePattern>,
    given: Labels,
    sidecars: HashMap<PathBuf, Vec<PathBuf>>,
    /// Files whose names did not fit the pattern, and takes labelled by a sidecar.
    pub unfit: Vec<PathBuf>,
    pub from_sidecar: usize,
}

impl Labelling {
    pub fn new(
        args: &IngestArgs,
        sidecars: HashMap<PathBuf, Vec<PathBuf>>,
    ) -> Result<Self, String> {
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
    pub fn of(&mut self, sources: &Sources, path: &Path) -> Result<Option<String>, String> {
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
                labels.merge(&sidecar_labels(sources, f)?)?;
            }
            self.from_sidecar += 1;
        }
        labels.merge(&self.given)?;
        Ok((!labels.is_empty()).then(|| serde_json::to_string(&labels).expect("labels serialise")))
    }
}
