//! `mocapstore bench --search`: how well motion features find motion by motion
//! ([`mocapstore::motion::retrieval`]), printed as a table with the confusions left.

use std::path::PathBuf;
use std::process::ExitCode;

use mocapstore::codec::features;
use mocapstore::motion::features::{Features, DIMS, KEY_ROLES, WINDOW};
use mocapstore::motion::formats::{self, ReadOptions};
use mocapstore::motion::retrieval::{self, content_label, Labelled};

fn load(path: &PathBuf) -> Result<Option<Labelled>, String> {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let Some(label) = content_label(&stem) else {
        return Ok(None);
    };
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    let loaded = formats::read(&bytes, &ReadOptions::default()).map_err(|e| e.to_string())?;
    retrieval::labelled(&loaded.motion, loaded.up.as_ref(), label)
        .map(Some)
        .map_err(|e| e.to_string())
}

pub fn run(files: &[PathBuf]) -> ExitCode {
    let started = std::time::Instant::now();
    let mut takes = Vec::new();
    for path in files {
        match load(path) {
            Ok(Some(t)) => takes.push(t),
            Ok(None) => {}
            Err(e) => eprintln!("{}: {e}; left out", path.display()),
        }
    }
    let read_s = started.elapsed().as_secs_f64();
    let Some(r) = retrieval::measure(&takes) else {
        eprintln!(
            "mocapstore bench --search: no content label with 6 takes among {} named \
             <dataset>_<content>_<style>_<n>",
            takes.len()
        );
        return ExitCode::from(2);
    };
    println!(
        "{} takes read ({} windows of {DIMS} numbers) in {read_s:.1} s; {} queries (labels \
         with at least 6 takes: {})",
        takes.len(),
        takes.iter().map(|t| t.windows.len()).sum::<usize>(),
        r.queries,
        r.labels
            .iter()
            .map(|(k, c)| format!("{k} {c}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    // The same, from the descriptors as the server stores them (codec::features).
    let mut stored_bytes = 0usize;
    let stored: Vec<Labelled> = takes
        .iter()
        .map(|t| {
            let f = Features {
                windows: t.windows.clone(),
                placed: KEY_ROLES.to_vec(),
                leg_m: None,
            };
            let frames = t.windows.last().map_or(0, |w| w.start + WINDOW);
            let bytes = features::encode(&f, true, frames).expect("features encode");
            stored_bytes += bytes.len();
            let back = features::decode(&bytes, u64::MAX).expect("features decode");
            let mut t = t.clone();
            for (w, d) in t.windows.iter_mut().zip(back.windows) {
                w.descriptor = d;
            }
            t
        })
        .collect();
    let s = retrieval::measure(&stored).expect("the same labels");
    let windows: usize = takes.iter().map(|t| t.windows.len()).sum();
    println!();
    println!(
        "| query | precision@5, features | as stored ({:.0} bytes a window) | precision@5, \
         mean pose (baseline) |",
        stored_bytes as f64 / windows.max(1) as f64
    );
    println!("|---|---:|---:|---:|");
    println!(
        "| whole take | {:.3} | {:.3} | {:.3} |",
        r.whole.0, s.whole.0, r.whole.1
    );
    println!(
        "| 1 s window ({}) | {:.3} | {:.3} | {:.3} |",
        r.windows_asked, r.window.0, s.window.0, r.window.1
    );
    println!();
    println!("Confusions among the 5 nearest takes (query label → found label: count):");
    let mut c: Vec<_> = r.confusions.into_iter().collect();
    c.sort_by_key(|e| std::cmp::Reverse(e.1));
    for ((a, b), k) in c.iter().take(12) {
        println!("  {a} → {b}: {k}");
    }
    ExitCode::SUCCESS
}
