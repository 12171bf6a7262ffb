//! The `spca` encoder: normalise by the torso, cut into segments, fit each a PCA model, key
//! its coefficient trajectories, and search the one tolerance scale every step follows
//! from for the fewest bytes that meet the bound.
//!
//! Every tolerance of the paper is a fixed share of one scale `s` (take units):
//! - PCA tolerance `s` (foot points `s/3`: the paper's 10 mm against 30 mm);
//! - coefficient key threshold and key step `s/2` (a coefficient error moves a pose by at
//!   most as much, since components are unit vectors);
//! - torso key threshold and step `s/5`: a torso error turns the whole body, and a hand a
//!   metre out moves about three times as far as the shoulder that turned it;
//! - model means at `s/10`, components at about `s/10` of pose movement.
//!
//! Under a max bound the residual layer ([`crate::codec::residual`]) holds every sample
//! within it, and `s` is searched for the fewest bytes of both layers together; under a mean
//! bound `s` is the largest at which the decoded mean meets it.

use std::cell::RefCell;
use std::ops::Range;

use super::coder::{ChunkKeys, Coder};
use super::model::{Analysis, Truncation};
use super::params::Params;
use super::spline::{self, Keys};
use super::torso::{self, to_local};
use crate::codec::entropy::Encoder;
use crate::codec::error::{Error, Result};
use crate::codec::measure::max_mean;
use crate::codec::rate::{largest_meeting, walk_grid, Best, Trial};
use crate::codec::{residual, segment, ChunkOut, CodecOutput, Input, Target};

/// The longest segment, frames: a longer one is split evenly. Segments are chunks, and a
/// range read decodes whole chunks.
pub const MAX_SEGMENT: usize = 4096;

/// Tolerances as shares of the scale `s` (module docs).
const FOOT: f64 = 1.0 / 3.0;
const COEF: f64 = 0.5;
const TORSO: f64 = 0.2;
const MEAN: f64 = 0.1;
const BASIS: f64 = 0.1;

/// Which parts of the method run: the paper's Table 3 compares PCA of the whole take, PCA
/// per segment, and both with key frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Options {
    /// Cut the take into segments (else one model for the whole take).
    pub segmented: bool,
    /// Key frames and splines (else every frame is a key).
    pub keyframes: bool,
}

impl Options {
    pub const SPCA: Options = Options {
        segmented: true,
        keyframes: true,
    };
}

/// A take prepared for trials: its normalisation, segments and their PCA.
pub struct Take<'a> {
    input: &'a Input<'a>,
    options: Options,
    torso: Option<(u8, [usize; 3])>,
    /// The points the models code.
    posed: Vec<usize>,
    segments: Vec<Range<usize>>,
    analyses: Vec<Analysis>,
    /// Each segment's truncation errors by component count, grown as trials ask.
    truncations: RefCell<Vec<Truncation>>,
    blend: usize,
}

/// The frames over which neighbouring models blend: the paper's 10–20 at 120 fps, scaled.
pub fn blend_frames(fps: f64) -> usize {
    ((15.0 * fps / 120.0).round() as usize).clamp(1, 64)
}

impl<'a> Take<'a> {
    pub fn new(input: &'a Input<'a>, options: Options) -> Result<Take<'a>> {
        let (frames, points) = (input.frames, input.points);
        let torso = input
            .torso
            .or_else(|| torso::find(input.names))
            .map(|t| (torso::vertical_axis(input.data, points, input.valid), t));
        let posed: Vec<usize> = (0..points)
            .filter(|p| torso.is_none_or(|(_, t)| !t.contains(p)))
            .collect();
        if posed.is_empty() {
            return Err(Error::Invalid(
                "spca needs points beside the torso's three".into(),
            ));
        }
        let feet = torso::feet(input.names, points);
        let share: Vec<f64> = posed
            .iter()
            .map(|&p| if feet[p] { FOOT } else { 1.0 })
            .collect();
        let width = 3 * posed.len();
        let up = torso.map_or(0, |(up, _)| up);
        let normalised = normalise(input.data, input.width(), &posed, up, |row| match torso {
            Some((up, t)) => {
                let tv: Vec<f64> = t
                    .iter()
                    .flat_map(|&p| (0..3).map(move |a| f64::from(row[p * 3 + a])))
                    .collect();
                torso::placement(&tv, up)
            }
            None => torso::Placement::IDENTITY,
        });
        let cuts = if options.segmented {
            segment::cuts(&normalised, width, &segment::Params::at(input.fps))
        } else {
            Vec::new()
        };
        let segments = segment::pieces(&cuts, frames, MAX_SEGMENT);
        let analyses: Vec<Analysis> = segments
            .iter()
            .map(|r| Analysis::of(&normalised[r.start * width..r.end * width], width))
            .collect();
        let truncations = segments
            .iter()
            .zip(&analyses)
            .map(|(r, a)| Truncation::new(a, &normalised[r.start * width..r.end * width], &share))
            .collect();
        Ok(Take {
            input,
            options,
            torso,
            posed,
            segments,
            analyses,
            truncations: RefCell::new(truncations),
            blend: blend_frames(input.fps),
        })
    }

    /// The segments (frame ranges), one chunk each.
    pub fn segments(&self) -> &[Range<usize>] {
        &self.segments
    }

    fn width(&self) -> usize {
        3 * self.posed.len()
    }

    /// Code the take at scale `s`, with the residual layer at `residual_t` (0: none).
    fn trial(&self, s: f64, residual_t: f64) -> Result<Trial> {
        let mut truncations = self.truncations.borrow_mut();
        let models = truncations
            .iter_mut()
            .zip(&self.analyses)
            .map(|(t, a)| a.model(t.components_for(a, s), MEAN * s, BASIS * s))
            .collect();
        drop(truncations);
        let params = Params {
            torso: self.torso,
            blend: self.blend,
            torso_step: TORSO * s,
            coef_step: COEF * s,
            mean_step: MEAN * s,
            residual_t,
            models,
        };
        let coder = Coder::new(params, self.input.points);
        let (points, w) = (self.input.points, self.input.width());
        let mut decoded = vec![0f32; self.input.data.len()];
        let mut chunks = Vec::with_capacity(self.segments.len());
        for (i, r) in self.segments.iter().enumerate() {
            let keys = self.keys(&coder, i, r.clone(), s);
            let n = r.len();
            let mut enc = Encoder::new();
            coder.code(&mut enc, n, Some(&keys))?;
            let recon = &mut decoded[r.start * w..r.end * w];
            coder.reconstruct(&keys, n, recon);
            if residual_t > 0.0 {
                let orig = &self.input.data[r.start * w..r.end * w];
                let valid = self
                    .input
                    .valid
                    .map(|v| &v[r.start * points..r.end * points]);
                residual::encode(&mut enc, orig, recon, valid, points, residual_t);
            }
            chunks.push(ChunkOut {
                frames: n,
                bytes: enc.finish(),
            });
        }
        let (max, mean) = max_mean(self.input.data, &decoded, self.input.valid);
        let params = coder.params.to_bytes();
        Ok(Trial::new(CodecOutput { params, chunks }, max, mean))
    }

    /// Segment `i`'s keys at scale `s`: the torso's, then its coefficients' from the poses
    /// normalised by the torso as the decoder will have it, then the next model's over the
    /// blend.
    fn keys(&self, coder: &Coder, i: usize, r: Range<usize>, s: f64) -> ChunkKeys {
        let (n, w, width) = (r.len(), self.input.width(), self.width());
        let threshold = |x: f64| if self.options.keyframes { x } else { 0.0 };
        let column = |rows: &dyn Fn(usize) -> f64| (0..n).map(rows).collect::<Vec<_>>();
        let torso = match self.torso {
            Some((_, t)) => (0..9)
                .map(|c| {
                    let (p, a) = (t[c / 3], c % 3);
                    let x = column(&|f| f64::from(self.input.data[(r.start + f) * w + p * 3 + a]));
                    spline::fit(&x, threshold(TORSO * s), TORSO * s)
                })
                .collect(),
            None => Vec::new(),
        };
        let mut keys = ChunkKeys {
            segment: i,
            torso,
            coefs: Vec::new(),
            lead: Vec::new(),
        };
        let (placed, _) = coder.placements(&keys, n);
        let up = self.torso.map_or(0, |(up, _)| up);
        let mut next = placed.iter();
        let rows = normalise(
            &self.input.data[r.start * w..r.end * w],
            w,
            &self.posed,
            up,
            |_| *next.next().expect("a placement per frame"),
        );
        let trajectories = |model: &super::model::Model, rows: &[f64]| -> Vec<Keys> {
            let c = model.coefficients(rows);
            (0..model.k())
                .map(|j| {
                    let x: Vec<f64> = c.row(j).iter().copied().collect();
                    spline::fit(&x, threshold(COEF * s), COEF * s)
                })
                .collect()
        };
        let models = &coder.params.models;
        keys.coefs = trajectories(&models[i], &rows);
        let lead = coder.lead_frames(i, n);
        if lead > 0 {
            keys.lead = trajectories(&models[i + 1], &rows[(n - lead) * width..]);
        }
        keys
    }

    /// Search the scale for the fewest bytes that meet `target`.
    ///
    /// Scales lie on a grid of quarter octaves around the tighter bound `t`:
    /// `s = t · 2^((j − 32)/4)`. The residual layer holds every sample to the max at any
    /// scale, and bytes fall and then rise with it. Under a max bound alone every scale
    /// meets it; a mean bound's error grows with the scale, so first the largest grid scale
    /// that meets it is found (galloping from `t`), and the search stays at or below it.
    ///
    /// Then half-octave steps from `s = 2t` (where most corpus takes come out smallest under
    /// a max bound: 261 of 345 take-bounds at 2–2.4t), or from the largest that meets the
    /// mean if that is smaller, in whichever direction bytes fall, until two steps in a row
    /// find nothing smaller; then the quarter octaves beside the best.
    pub fn encode(&self, target: Target) -> Result<CodecOutput> {
        const START: usize = 36;
        const GRID: std::ops::RangeInclusive<usize> = 8..=64;
        let t = target.tightest();
        let mut search = ScaleSearch {
            take: self,
            target,
            t,
            tried: std::collections::HashMap::new(),
            best: Best::new(target),
        };
        let top = match target.mean {
            None => *GRID.end(),
            Some(_) => {
                let top = largest_meeting(Some(32), |j| {
                    let j = j as usize;
                    Ok(j <= *GRID.end() && search.bytes(j)?.is_some())
                })?;
                match top {
                    Some(j) if j as usize >= *GRID.start() => j as usize,
                    _ => {
                        return Err(Error::BoundMissed {
                            codec: "spca".into(),
                            detail: format!(
                                "no scale down to {:.3e} meets {target}",
                                search.scale(*GRID.start())
                            ),
                        })
                    }
                }
            }
        };
        walk_grid(START.min(top), 2, GRID, top, |j| search.better(j))?;
        let (trial, _) = search.best.into_best().ok_or_else(|| Error::BoundMissed {
            codec: "spca".into(),
            detail: format!("no scale meets {target}"),
        })?;
        Ok(trial.out)
    }
}

/// The trials of [`Take::encode`]'s search over the scale grid: each grid index coded once,
/// the smallest trial that meets the target kept.
struct ScaleSearch<'s, 'a> {
    take: &'s Take<'a>,
    target: Target,
    t: f64,
    /// Grid index → its size if it met the target.
    tried: std::collections::HashMap<usize, Option<usize>>,
    best: Best<usize>,
}

impl ScaleSearch<'_, '_> {
    fn scale(&self, j: usize) -> f64 {
        self.t * 2f64.powf((j as f64 - 32.0) / 4.0)
    }

    /// Grid index `j`'s size if it meets the target.
    fn bytes(&mut self, j: usize) -> Result<Option<usize>> {
        if let Some(&r) = self.tried.get(&j) {
            return Ok(r);
        }
        let trial = self.take.trial(self.scale(j), self.target.max)?;
        let r = self.best.offer(trial, j);
        self.tried.insert(j, r);
        Ok(r)
    }

    /// Whether grid index `j` meets the target with fewer bytes than any before it.
    fn better(&mut self, j: usize) -> Result<bool> {
        let before = self.best.bytes();
        let r = self.bytes(j)?;
        Ok(r.is_some_and(|b| before.is_none_or(|x| b < x)))
    }
}

/// The posed points of each frame of `data` (`frames × w`) in the body's frame that
/// `placement` gives for that frame's row: `frames × 3·posed`.
fn normalise(
    data: &[f32],
    w: usize,
    posed: &[usize],
    up: u8,
    mut placement: impl FnMut(&[f32]) -> torso::Placement,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(data.len() / w.max(1) * 3 * posed.len());
    for row in data.chunks_exact(w) {
        let placed = placement(row);
        for &p in posed {
            let x = [0, 1, 2].map(|a| f64::from(row[p * 3 + a]));
            out.extend_from_slice(&to_local(&placed, up, x));
        }
    }
    out
}
