//! `mocapstore bench --search`: how well motion features ([`features`]) find motion by
//! motion, on takes named `<dataset>_<content>_<style>_<n>` (Bandai Namco's): leave-one-out
//! precision@5 of the content label, with the whole take as the query and with a 1 s
//! window as the query (its own take left out), beside a plain baseline (the distance
//! between the takes' mean poses, pelvis-relative, as captured), and the confusions left.
//!
//! Each file is read and given the read path's transforms (30 fps, metres, +Y up by its
//! body), then one point per body role, as the server's features are taken.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use mocapstore::motion::body::{Axis, Body, Given, Role};
use mocapstore::motion::features::{self, Window, DIMS, RATE};
use mocapstore::motion::formats::{self, ReadOptions};
use mocapstore::motion::moments::centroids;
use mocapstore::motion::transform::{whole, Options};

/// A take as the search sees it.
struct Take {
    content: String,
    windows: Vec<Window>,
    /// Its mean pose, pelvis-relative, as captured (the baseline).
    mean_pose: Vec<f64>,
}

/// The content label of a file named `<dataset>_<content>_<style>_<n>`.
fn content(stem: &str) -> Option<String> {
    let parts: Vec<&str> = stem.split('_').collect();
    (parts.len() == 4).then(|| parts[1].to_string())
}

fn load(path: &PathBuf) -> Result<Option<Take>, String> {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let Some(content) = content(&stem) else {
        return Ok(None);
    };
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    let loaded = formats::read(&bytes, &ReadOptions::default()).map_err(|e| e.to_string())?;
    let body = Body::of(&loaded.motion, Given::default(), loaded.up.as_ref())
        .map_err(|e| e.to_string())?;
    let shaped = whole::apply(
        &loaded.motion,
        &body,
        &Options {
            fps: Some(RATE),
            up: Some(Axis::Y),
            metres_per_unit: Some(1.0),
            ..Options::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let names = &shaped.point_names;
    let groups: Vec<Vec<usize>> = Role::all()
        .into_iter()
        .map(|r| body.roles.points(r, names))
        .collect();
    let roles = centroids(shaped.positions(), names.len(), &groups);
    let windows = features::features(&roles).windows;
    // The baseline: each role's mean place from the pelvis, as captured.
    let width = groups.len() * 3;
    let mut sum = vec![0.0; width];
    let mut n = 0.0f64;
    for f in roles.chunks_exact(width) {
        if f[..3].iter().any(|v| v.is_nan()) {
            continue;
        }
        for (i, v) in f.iter().enumerate() {
            if !v.is_nan() {
                sum[i] += f64::from(*v - f[i % 3]);
            }
        }
        n += 1.0;
    }
    let mean_pose = sum.iter().map(|s| s / n.max(1.0)).collect();
    Ok(Some(Take {
        content,
        windows,
        mean_pose,
    }))
}

fn dist(a: &[f32; DIMS], b: &[f32; DIMS]) -> f64 {
    f64::from(features::distance(a, b)).sqrt()
}

/// How far window `w` lies from take `t`: its nearest window's distance.
fn nearest(w: &[f32; DIMS], t: &Take) -> f64 {
    t.windows
        .iter()
        .map(|x| dist(w, &x.descriptor))
        .fold(f64::INFINITY, f64::min)
}

/// The distance between two takes: each one's windows' mean distance to the other's
/// nearest, both ways, each window weighted by how much it moves ([`features::energy`]:
/// the still windows most takes begin and end with tell little).
fn take_distance(a: &Take, b: &Take) -> f64 {
    let one = |x: &Take, y: &Take| {
        let (mut sum, mut weight) = (0.0, 0.0);
        for w in &x.windows {
            let e = features::energy(&w.descriptor);
            sum += e * nearest(&w.descriptor, y);
            weight += e;
        }
        sum / weight.max(1e-9)
    };
    (one(a, b) + one(b, a)) / 2.0
}

fn baseline_distance(a: &Take, b: &Take) -> f64 {
    a.mean_pose
        .iter()
        .zip(&b.mean_pose)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// The share of the 5 nearest (by `scores`, lower nearer) whose content is `content`.
fn precision_at_5(mut scores: Vec<(f64, &str)>, content: &str) -> f64 {
    scores.sort_by(|a, b| a.0.total_cmp(&b.0));
    scores.iter().take(5).filter(|s| s.1 == content).count() as f64 / 5.0
}

pub fn run(files: &[PathBuf]) -> ExitCode {
    let started = std::time::Instant::now();
    let mut takes = Vec::new();
    for path in files {
        match load(path) {
            Ok(Some(t)) if !t.windows.is_empty() => takes.push(t),
            Ok(_) => {}
            Err(e) => eprintln!("{}: {e}; left out", path.display()),
        }
    }
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for t in &takes {
        *counts.entry(t.content.as_str()).or_default() += 1;
    }
    // Queries: takes whose content has at least 5 others to find.
    let queries: Vec<usize> = (0..takes.len())
        .filter(|&i| counts[takes[i].content.as_str()] >= 6)
        .collect();
    if queries.is_empty() {
        eprintln!(
            "mocapstore bench --search: no content label with 6 takes among {} named \
             <dataset>_<content>_<style>_<n>",
            takes.len()
        );
        return ExitCode::from(2);
    }
    let read_s = started.elapsed().as_secs_f64();
    let (mut whole, mut base, mut window, mut window_base) = (0.0, 0.0, 0.0, 0.0);
    let mut windows_asked = 0usize;
    let mut confusion: BTreeMap<(String, String), usize> = BTreeMap::new();
    for &q in &queries {
        let query = &takes[q];
        let others = || (0..takes.len()).filter(move |&j| j != q);
        let scores: Vec<(f64, &str)> = others()
            .map(|j| (take_distance(query, &takes[j]), takes[j].content.as_str()))
            .collect();
        let mut sorted = scores.clone();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        for s in sorted.iter().take(5).filter(|s| s.1 != query.content) {
            *confusion
                .entry((query.content.clone(), s.1.to_string()))
                .or_default() += 1;
        }
        whole += precision_at_5(scores, &query.content);
        base += precision_at_5(
            others()
                .map(|j| {
                    (
                        baseline_distance(query, &takes[j]),
                        takes[j].content.as_str(),
                    )
                })
                .collect(),
            &query.content,
        );
        // 1 s windows of the take, every other one, each as a query.
        for w in query.windows.iter().step_by(2) {
            let scores = others()
                .map(|j| (nearest(&w.descriptor, &takes[j]), takes[j].content.as_str()))
                .collect();
            window += precision_at_5(scores, &query.content);
            windows_asked += 1;
        }
        window_base += precision_at_5(
            others()
                .map(|j| {
                    (
                        baseline_distance(query, &takes[j]),
                        takes[j].content.as_str(),
                    )
                })
                .collect(),
            &query.content,
        ) * query.windows.iter().step_by(2).count() as f64;
    }
    let n = queries.len() as f64;
    println!(
        "{} takes read ({} windows of {} numbers) in {read_s:.1} s; {} queries (contents with \
         at least 6 takes: {})",
        takes.len(),
        takes.iter().map(|t| t.windows.len()).sum::<usize>(),
        DIMS,
        queries.len(),
        counts
            .iter()
            .filter(|(_, c)| **c >= 6)
            .map(|(k, c)| format!("{k} {c}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!();
    println!("| query | precision@5, features | precision@5, mean pose (baseline) |");
    println!("|---|---:|---:|");
    println!("| whole take | {:.3} | {:.3} |", whole / n, base / n);
    println!(
        "| 1 s window ({windows_asked}) | {:.3} | {:.3} |",
        window / windows_asked as f64,
        window_base / windows_asked as f64
    );
    println!();
    println!("Confusions among the 5 nearest takes (query content → found content: count):");
    let mut c: Vec<_> = confusion.into_iter().collect();
    c.sort_by_key(|e| std::cmp::Reverse(e.1));
    for ((a, b), k) in c.iter().take(12) {
        println!("  {a} → {b}: {k}");
    }
    ExitCode::SUCCESS
}
