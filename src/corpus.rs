//! The real-data corpus that tests and benchmarks run on: where it is (`MOCAP_CORPUS`,
//! default `../shared/data` beside the crate) and its `manifest.csv`, the frame and point
//! counts an independent parser found for each file.

use std::path::{Path, PathBuf};

/// One row of `manifest.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// Relative to the corpus root.
    pub path: String,
    pub format: String,
    pub points: Option<usize>,
    pub frames: Option<usize>,
    pub fps: Option<f64>,
    /// Whether the reference parser read the file; `None` where it was not run (TRC).
    pub reference_ok: Option<bool>,
}

/// The corpus root: `$MOCAP_CORPUS`, else `../shared/data` relative to the crate root.
pub fn root() -> PathBuf {
    match std::env::var_os("MOCAP_CORPUS") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
    }
}

/// The corpus for a test or benchmark, with its manifest, checked whole: every file the
/// manifest lists is there.
///
/// - `MOCAP_CORPUS` set: the corpus must be there, whole; if not, this panics (the test
///   fails), so CI can never pass on a corpus it did not read.
/// - not set, and nothing at the default `../shared/data`: `None`, after one loud line on
///   stderr, so that a clone on its own (a newcomer's) passes the tests that need no
///   corpus. `scripts/fetch-corpus` fetches the public files.
pub fn for_tests() -> Option<(PathBuf, Vec<Entry>)> {
    // Read and checked once per test binary: many tests ask.
    static FOUND: std::sync::OnceLock<Option<(PathBuf, Vec<Entry>)>> = std::sync::OnceLock::new();
    FOUND.get_or_init(find_for_tests).clone()
}

fn find_for_tests() -> Option<(PathBuf, Vec<Entry>)> {
    let explicit = std::env::var_os("MOCAP_CORPUS").is_some_and(|p| !p.is_empty());
    let root = root();
    let entries = match manifest(&root) {
        Ok(m) => m,
        Err(e) if explicit => panic!("MOCAP_CORPUS is set, but {e}"),
        Err(_) => {
            // Past the test harness's capture of `eprintln!` (it hides a passing test's
            // output): a skip must be seen.
            use std::io::Write;
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED (no corpus): nothing at {}; set MOCAP_CORPUS or run \
                 scripts/fetch-corpus to run the corpus tests",
                root.display()
            );
            return None;
        }
    };
    let missing: Vec<&str> = entries
        .iter()
        .filter(|e| !root.join(&e.path).is_file())
        .map(|e| e.path.as_str())
        .collect();
    assert!(
        !entries.is_empty() && missing.is_empty(),
        "the corpus at {} is not whole: {} of {} manifest files missing (first: {:?})",
        root.display(),
        missing.len(),
        entries.len(),
        missing.first()
    );
    Some((root, entries))
}

/// Read and parse `manifest.csv` under `root`.
pub fn manifest(root: &Path) -> Result<Vec<Entry>, String> {
    let path = root.join("manifest.csv");
    let text = std::fs::read_to_string(&path).map_err(|e| {
        format!(
            "cannot read {}: {e} (set MOCAP_CORPUS to the corpus folder)",
            path.display()
        )
    })?;
    parse_manifest(&text)
}

fn parse_manifest(text: &str) -> Result<Vec<Entry>, String> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().ok_or("empty manifest")?.split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| h.trim() == name)
            .ok_or(format!("manifest has no {name} column"))
    };
    let (c_path, c_fmt, c_pts, c_frames, c_fps, c_ok) = (
        col("path")?,
        col("format")?,
        col("points")?,
        col("frames")?,
        col("fps")?,
        col("reference_parser_ok")?,
    );
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let get = |i: usize| f.get(i).map(|s| s.trim()).unwrap_or("");
            Ok(Entry {
                path: get(c_path).to_string(),
                format: get(c_fmt).to_string(),
                points: get(c_pts).parse().ok(),
                frames: get(c_frames).parse().ok(),
                fps: get(c_fps).parse().ok(),
                reference_ok: match get(c_ok) {
                    "True" => Some(true),
                    "False" => Some(false),
                    _ => None,
                },
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_rows_with_blanks() {
        let m = parse_manifest(
            "path,format,points,frames,fps,reference_parser_ok,sha256\n\
             a.bvh,bvh,22,128,30.0,True,x\nb.c3d,c3d,,,,False,y\nc.trc,trc,,,,,z\n",
        )
        .unwrap();
        assert_eq!(m.len(), 3);
        assert_eq!(m[0].points, Some(22));
        assert_eq!(m[1].reference_ok, Some(false));
        assert_eq!(m[2].reference_ok, None);
    }
}
