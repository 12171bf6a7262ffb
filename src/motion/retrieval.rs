//! How well motion features ([`super::features`]) find motion by motion, measured on takes
//! that carry a label (Bandai Namco's content, from `<dataset>_<content>_<style>_<n>`):
//! leave-one-out precision@5 of the label, with the whole take as the query and with a 1 s
//! window as the query (its own take left out, at most one result per take), beside a
//! plain baseline: the distance between the takes' mean poses, pelvis-relative, as
//! captured. What `mocapstore bench --search` prints and a corpus test holds the features
//! to.
//!
//! A take is given the read path's transforms (30 fps, metres, +Y up by its body) and then
//! one point per body role, as the server's features are taken.

use std::collections::BTreeMap;

use super::body::{Prior, Role};
use super::features::{self, Window, DIMS};
use super::similar::{self, Shared};
use super::Motion;

/// A labelled take as the measure sees it.
#[derive(Debug, Clone)]
pub struct Labelled {
    pub label: String,
    pub windows: Vec<Window>,
    /// Its mean pose, pelvis-relative, as captured: the baseline's descriptor of the take,
    /// and of each window.
    pub mean_pose: Vec<f64>,
    pub window_poses: Vec<Vec<f64>>,
}

/// The content label of a file named `<dataset>_<content>_<style>_<n>`.
pub fn content_label(stem: &str) -> Option<String> {
    let parts: Vec<&str> = stem.split('_').collect();
    (parts.len() == 4).then(|| parts[1].to_string())
}

/// `m` (with the format's `prior` on up) as the measure sees it, labelled `label`.
pub fn labelled(m: &Motion, prior: Option<&Prior>, label: String) -> super::Result<Labelled> {
    let taken = features::of_motion(m, prior)?;
    let width = Role::all().len() * 3;
    let frames: Vec<&[f32]> = taken.roles.chunks_exact(width).collect();
    let windows = taken.features.windows;
    let window_poses = windows
        .iter()
        .map(|w| mean_pose(&frames[w.start..(w.start + features::WINDOW).min(frames.len())]))
        .collect();
    Ok(Labelled {
        label,
        windows,
        mean_pose: mean_pose(&frames),
        window_poses,
    })
}

/// The mean of each role's place from the pelvis over `frames` (where both are placed).
fn mean_pose(frames: &[&[f32]]) -> Vec<f64> {
    let width = frames.first().map_or(0, |f| f.len());
    let mut sum = vec![0.0; width];
    let mut n = 0.0f64;
    for f in frames {
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
    sum.iter().map(|s| s / n.max(1.0)).collect()
}

fn pose_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// How far window `w` lies from take `t`: its nearest window's distance.
fn nearest(w: &[f32; DIMS], t: &Labelled) -> f64 {
    take_distance_of(std::slice::from_ref(w), t)
}

fn take_distance_of(query: &[[f32; DIMS]], t: &Labelled) -> f64 {
    let windows: Vec<[f32; DIMS]> = t.windows.iter().map(|w| w.descriptor).collect();
    similar::best_run(query, &windows, &Shared::all()).map_or(f64::INFINITY, |r| r.score)
}

/// The distance between two takes: the search's score of `b`'s best run for the whole of
/// `a` as the query ([`similar::best_run`]).
pub fn take_distance(a: &Labelled, b: &Labelled) -> f64 {
    let query: Vec<[f32; DIMS]> = a.windows.iter().map(|w| w.descriptor).collect();
    take_distance_of(&query, b)
}

/// The baseline's distance: between the takes' mean poses.
pub fn baseline_distance(a: &Labelled, b: &Labelled) -> f64 {
    pose_distance(&a.mean_pose, &b.mean_pose)
}

/// The share of the 5 nearest (by `scores`, lower nearer) labelled `label`.
fn precision_at_5(mut scores: Vec<(f64, &str)>, label: &str) -> f64 {
    scores.sort_by(|a, b| a.0.total_cmp(&b.0));
    scores.iter().take(5).filter(|s| s.1 == label).count() as f64 / 5.0
}

/// What the measure found.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Queries: takes whose label has at least 5 others to find, with each label's count.
    pub queries: usize,
    pub labels: BTreeMap<String, usize>,
    /// Precision@5 with the whole take as the query: features, baseline.
    pub whole: (f64, f64),
    /// Precision@5 with a 1 s window as the query (every other window of each query take),
    /// and how many: features, baseline (the window's mean pose against each other take's
    /// nearest window's).
    pub window: (f64, f64),
    pub windows_asked: usize,
    /// (query label, found label) → how often the found one was among the 5 nearest.
    pub confusions: BTreeMap<(String, String), usize>,
}

/// Leave-one-out precision@5 over `takes`; `None` when no label has 6 takes.
pub fn measure(takes: &[Labelled]) -> Option<Report> {
    let mut labels: BTreeMap<String, usize> = BTreeMap::new();
    for t in takes {
        *labels.entry(t.label.clone()).or_default() += 1;
    }
    let queries: Vec<usize> = (0..takes.len())
        .filter(|&i| labels[&takes[i].label] >= 6 && !takes[i].windows.is_empty())
        .collect();
    if queries.is_empty() {
        return None;
    }
    let (mut whole, mut base, mut window, mut window_base) = (0.0, 0.0, 0.0, 0.0);
    let mut windows_asked = 0usize;
    let mut confusions: BTreeMap<(String, String), usize> = BTreeMap::new();
    for &q in &queries {
        let query = &takes[q];
        let others = || (0..takes.len()).filter(move |&j| j != q && !takes[j].windows.is_empty());
        let mut scores: Vec<(f64, &str)> = others()
            .map(|j| (take_distance(query, &takes[j]), takes[j].label.as_str()))
            .collect();
        scores.sort_by(|a, b| a.0.total_cmp(&b.0));
        for s in scores.iter().take(5).filter(|s| s.1 != query.label) {
            *confusions
                .entry((query.label.clone(), s.1.to_string()))
                .or_default() += 1;
        }
        whole += precision_at_5(scores, &query.label);
        base += precision_at_5(
            others()
                .map(|j| (baseline_distance(query, &takes[j]), takes[j].label.as_str()))
                .collect(),
            &query.label,
        );
        for (w, pose) in query.windows.iter().zip(&query.window_poses).step_by(2) {
            let scores = others()
                .map(|j| (nearest(&w.descriptor, &takes[j]), takes[j].label.as_str()))
                .collect();
            window += precision_at_5(scores, &query.label);
            let poses = others()
                .map(|j| {
                    let d = takes[j]
                        .window_poses
                        .iter()
                        .map(|p| pose_distance(pose, p))
                        .fold(f64::INFINITY, f64::min);
                    (d, takes[j].label.as_str())
                })
                .collect();
            window_base += precision_at_5(poses, &query.label);
            windows_asked += 1;
        }
    }
    let n = queries.len() as f64;
    let w = windows_asked.max(1) as f64;
    Some(Report {
        queries: queries.len(),
        labels: labels.into_iter().filter(|(_, c)| *c >= 6).collect(),
        whole: (whole / n, base / n),
        window: (window / w, window_base / w),
        windows_asked,
        confusions,
    })
}
