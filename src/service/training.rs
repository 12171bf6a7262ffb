//! Training shared bases: select takes of one layout, decode them, train an LSDT basis or
//! an MDTT basis set, store it with its provenance — as a background job ([`start_training`]).

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::bases::{Objective, Provenance, SetSize};
use super::jobs::{Job, Jobs, NewJob, Progress};
use super::take::Take;
use super::{blocking, Error, Result};
use crate::codec::lsdt::train::{train_basis_reporting, TrainOptions};
use crate::codec::mdtt::database::{train_set, SetOptions};
use crate::codec::{Basis, BasisKind, Input, Target};
use crate::store::{BasisRow, Filter, Store};

/// What to train and on which takes.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TrainRequest {
    /// `lsdt` (the default).
    pub kind: Option<BasisKind>,
    pub library: Option<String>,
    pub tag: Option<String>,
    /// Layout signature; needed when the selection spans several layouts.
    pub layout: Option<String>,
    /// Exactly these takes (instead of a library/tag/layout selection); never empty.
    pub ids: Option<Vec<String>>,
    /// Non-zeros per sample (the paper's P = 8).
    pub sparsity: Option<usize>,
    pub max_iterations: Option<usize>,
    /// Frames sampled (evenly) from the selection (lsdt).
    pub max_samples: Option<usize>,
    /// Candidate numbers of bases (mdtt-set); the smallest total size wins.
    pub k: Option<Vec<usize>>,
    /// The bound at which candidate sets are compared (mdtt-set), mm; default 1.
    pub max_error_mm: Option<f64>,
}

/// A validated training request: the takes, all of one layout.
pub struct Selection {
    pub kind: BasisKind,
    pub layout: String,
    pub points: usize,
    pub takes: Vec<Take>,
    pub options: TrainOptions,
    pub max_samples: usize,
    pub set: SetOptions,
    pub bound_mm: f64,
}

/// Resolve a request to its takes, refusing what cannot be trained (nothing selected,
/// several layouts, a kind not trainable) before any job starts.
pub async fn select(store: &Store, req: &TrainRequest) -> Result<Selection> {
    let kind = req.kind.unwrap_or(BasisKind::Lsdt);
    let ks = req.k.clone().unwrap_or_else(|| SetOptions::default().ks);
    if ks.is_empty() || ks.iter().any(|&k| !(1..=32).contains(&k)) {
        return Err(Error::InvalidRequest(
            "k must list numbers of bases in 1..=32".into(),
        ));
    }
    let bound_mm = crate::codec::ErrorBound::from_request(req.max_error_mm, None)
        .map_err(|e| Error::InvalidRequest(e.to_string()))?
        .max_mm();
    let sparsity = req.sparsity.unwrap_or(8);
    let max_iterations = req.max_iterations.unwrap_or(50);
    let max_samples = req.max_samples.unwrap_or(50_000);
    if sparsity == 0 || !(1..=1000).contains(&max_iterations) || max_samples < 16 {
        return Err(Error::InvalidRequest(
            "sparsity must be ≥ 1, max_iterations 1..=1000, max_samples ≥ 16".into(),
        ));
    }
    let takes = selected_takes(store, req).await?;
    if takes.is_empty() {
        return Err(Error::InvalidRequest("the selection holds no takes".into()));
    }
    let mut layouts: Vec<(String, usize)> = Vec::new();
    for t in &takes {
        match layouts.iter_mut().find(|(l, _)| *l == t.layout) {
            Some((_, n)) => *n += 1,
            None => layouts.push((t.layout.clone(), 1)),
        }
    }
    if layouts.len() > 1 {
        let list: Vec<String> = layouts
            .iter()
            .map(|(l, n)| format!("{l} ({n} takes)"))
            .collect();
        return Err(Error::InvalidRequest(format!(
            "a basis is for one layout and the selection spans {}: {}; choose one with layout",
            layouts.len(),
            list.join(", ")
        )));
    }
    let points = takes[0].points;
    let most = match kind {
        BasisKind::Lsdt => crate::limits::LSDT_MAX_POINTS,
        BasisKind::MdttSet => crate::limits::MDTT_MAX_POINTS,
    };
    if points > most {
        return Err(Error::InvalidRequest(format!(
            "a {kind} basis is trained for layouts of at most {most} points; these takes have {points}"
        )));
    }
    Ok(Selection {
        kind,
        layout: layouts.remove(0).0,
        points: takes[0].points,
        takes,
        options: TrainOptions {
            sparsity,
            max_iterations,
            ..TrainOptions::default()
        },
        max_samples,
        set: SetOptions {
            ks,
            ..SetOptions::default()
        },
        bound_mm,
    })
}

/// The takes a request names: by id (each must exist), or by library, tag and layout.
async fn selected_takes(store: &Store, req: &TrainRequest) -> Result<Vec<Take>> {
    let mut takes = Vec::new();
    if let Some(ids) = &req.ids {
        if ids.is_empty() {
            return Err(Error::InvalidRequest(
                "ids is empty: name the takes, or leave ids out to select by library, tag and layout"
                    .into(),
            ));
        }
        if req.library.is_some() || req.tag.is_some() || req.layout.is_some() {
            return Err(Error::InvalidRequest(
                "give ids, or a library/tag/layout selection, not both".into(),
            ));
        }
        let mut missing = Vec::new();
        for id in ids {
            match super::fetch::take(store, id).await {
                Ok(t) => takes.push(t),
                Err(Error::NotFound(_)) => missing.push(id.as_str()),
                Err(e) => return Err(e),
            }
        }
        if !missing.is_empty() {
            return Err(Error::InvalidRequest(format!(
                "ids names takes that are not stored: {}",
                missing.join(", ")
            )));
        }
    } else {
        let filter = Filter {
            library: req.library.clone(),
            tag: req.tag.clone(),
            layout: req.layout.clone(),
            ..Filter::default()
        };
        takes = super::library::all_takes(store, &filter).await?;
    }
    Ok(takes)
}

/// Decode the selected takes, train, store the basis; reports progress as it goes.
pub async fn train(store: &Store, sel: Selection, progress: &Progress) -> Result<BasisRow> {
    let t0 = std::time::Instant::now();
    let n = sel.takes.len();
    let mut frames_mm: Vec<Vec<f32>> = Vec::with_capacity(n);
    for (i, t) in sel.takes.iter().enumerate() {
        progress.report(
            0.5 * i as f64 / n as f64,
            format!("decoding take {} of {n}", i + 1),
        );
        // Train in millimetres, so takes stored in other units weigh alike.
        let k = (t.metres_per_unit * 1000.0) as f32;
        let mut f = super::fetch::whole_take(store, t).await?;
        f.iter_mut().for_each(|v| *v *= k);
        frames_mm.push(f);
    }
    progress.report(0.5, format!("training {}", sel.kind));
    let (basis, mut provenance) = match sel.kind {
        BasisKind::Lsdt => train_lsdt(&sel, frames_mm, progress).await?,
        BasisKind::MdttSet => train_mdtt_set(&sel, frames_mm).await?,
    };
    provenance.takes = Some(sel.takes.iter().map(|t| t.id.clone()).collect());
    provenance.frames = Some(sel.takes.iter().map(|t| t.frames as u64).sum());
    provenance.seconds = Some(t0.elapsed().as_secs_f64());
    let row = basis_row(&sel, &basis, &provenance)?;
    if progress.is_lost() {
        return Err(Error::Conflict(
            "another server runs this job now (its lease ran out here)".into(),
        ));
    }
    store.insert_basis(&row).await?;
    Ok(row)
}

fn basis_row(sel: &Selection, basis: &Basis, provenance: &Provenance) -> Result<BasisRow> {
    let m = &basis.matrices()[0];
    Ok(BasisRow {
        id: basis.id(),
        kind: sel.kind.name().to_string(),
        layout: sel.layout.clone(),
        points: sel.points as i64,
        dims: format!("{}×{}×{}", basis.matrices().len(), m.rows, m.cols),
        payload: basis.bytes().to_vec(),
        provenance: provenance.to_value()?,
        created_at: super::now_ms(),
        used_by: 0,
    })
}

async fn train_lsdt(
    sel: &Selection,
    frames_mm: Vec<Vec<f32>>,
    progress: &Progress,
) -> Result<(Basis, Provenance)> {
    let (points, options, max_samples) = (sel.points, sel.options, sel.max_samples);
    let p2 = progress.clone();
    let trained = blocking(move || {
        let slices: Vec<&[f32]> = frames_mm.iter().map(Vec::as_slice).collect();
        train_basis_reporting(&slices, points, &options, max_samples, &mut |d| {
            p2.report(
                0.5 + 0.5 * (d + 1) as f64 / 3.0,
                format!("trained coordinate {} of 3", d + 1),
            );
        })
    })
    .await??;
    let axis = |d: usize| trained.runs[d].objective.clone();
    let provenance = Provenance {
        algorithm: "LSDT (Hou et al. 2016, Algorithm 1), DCT start, rows by energy".into(),
        samples: Some(trained.samples),
        sparsity: Some(options.sparsity),
        max_iterations: Some(options.max_iterations),
        tolerance: Some(options.tolerance),
        objective: Some(Objective::PerAxis {
            x: axis(0),
            y: axis(1),
            z: axis(2),
        }),
        ..Provenance::default()
    };
    Ok((trained.basis, provenance))
}

async fn train_mdtt_set(sel: &Selection, frames_mm: Vec<Vec<f32>>) -> Result<(Basis, Provenance)> {
    let points = sel.points;
    let fps: Vec<f64> = sel.takes.iter().map(|t| t.fps).collect();
    let (set, bound_mm) = (sel.set.clone(), sel.bound_mm);
    let trained = blocking(move || {
        let filled: Vec<(Vec<f32>, Vec<bool>)> = frames_mm
            .iter()
            .map(|f| {
                (
                    crate::codec::gaps::fill(f, points),
                    crate::codec::gaps::mask(f),
                )
            })
            .collect();
        let inputs: Vec<Input<'_>> = filled
            .iter()
            .zip(&fps)
            .map(|((data, valid), &fps)| Input {
                data,
                valid: Some(valid),
                frames: data.len() / (points * 3),
                points,
                fps,
                shared: None,
                skeleton: None,
                names: &[],
                torso: None,
            })
            .collect();
        // Frames are in millimetres here, so the bound is too.
        let targets = vec![Target::max(bound_mm); inputs.len()];
        train_set(&inputs, &targets, &set)
    })
    .await??;
    let sizes = trained
        .sizes
        .iter()
        .map(|&(k, takes_bytes, basis_bytes)| SetSize {
            k,
            takes_bytes: takes_bytes as u64,
            basis_bytes: basis_bytes as u64,
        })
        .collect();
    let provenance = Provenance {
        algorithm: "MDTT database mode (Hou et al. 2015): deterministic annealing, k-means++ seeds"
            .into(),
        clips: Some(trained.clips),
        rank: Some(trained.rank),
        k_candidates: Some(sizes),
        k: Some(trained.basis.matrices().len()),
        bound_mm: Some(sel.bound_mm),
        objective: Some(Objective::Series(trained.distortion)),
        ..Provenance::default()
    };
    Ok((trained.basis, provenance))
}

/// What training jobs are called in the job table.
pub const JOB_KIND: &str = "train-bases";

/// Start training in the background; obvious mistakes are refused before a job exists. An
/// identical request while one runs (on any server) gets that job.
pub async fn start_training(store: &Store, jobs: &Arc<Jobs>, req: TrainRequest) -> Result<Job> {
    let sel = select(store, &req).await?;
    let mut libraries: Vec<String> = sel.takes.iter().map(|t| t.library.clone()).collect();
    libraries.sort();
    libraries.dedup();
    let request = serde_json::to_value(&req).map_err(|e| Error::Internal(e.to_string()))?;
    let (job, runner) = jobs
        .start(NewJob {
            kind: JOB_KIND.into(),
            request,
            libraries,
        })
        .await?;
    if let Some(progress) = runner {
        run(store.clone(), sel, progress);
    }
    Ok(job)
}

/// Run again a training job taken over from a server that died (its stored `request`).
pub async fn resume(store: &Store, request: &str, progress: Progress) {
    let selected = match serde_json::from_str::<TrainRequest>(request) {
        Ok(req) => select(store, &req).await,
        Err(e) => Err(Error::Corrupt(format!("job {}: request: {e}", progress.id))),
    };
    match selected {
        Ok(sel) => run(store.clone(), sel, progress),
        // The database away again: leave the job to its lease, for whoever looks next.
        Err(Error::Store(e)) if e.is_unavailable() => {
            tracing::warn!(job = %progress.id, error = %e, "cannot run a job taken over yet");
        }
        // The takes it selected may have gone meanwhile.
        Err(e) => progress.fail(e.to_string()).await,
    }
}

/// Train `sel` in the background, reporting through `progress`.
fn run(store: Store, sel: Selection, progress: Progress) {
    tokio::spawn(async move {
        match train(&store, sel, &progress).await {
            Ok(row) => {
                progress
                    .succeed(serde_json::to_value(&row).unwrap_or_default())
                    .await
            }
            Err(e) => progress.fail(e.to_string()).await,
        }
    });
}
