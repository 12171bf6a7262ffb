//! The MDTT transform proper: clip DCTs, the covariance of their truncated coefficients,
//! its leading eigenvectors, and the inverse that encoder and decoder share.

use std::collections::HashMap;
use std::ops::Range;

use nalgebra::DMatrix;

use crate::codec::linalg::leading_eigen;

use super::params::Params;
use crate::codec::linalg::add_outer_products;
use crate::codec::simd::dispatch;
use crate::codec::{dct, segment, Input};

/// Clip length: the paper's 280 frames at 120 fps, scaled to the take's frame rate.
pub fn clip_len(fps: f64) -> usize {
    ((280.0 * fps / 120.0).round() as usize).clamp(8, crate::codec::MAX_CLIP)
}

/// The paper's ratio r = l/k = 0.1·⌈L/50⌉, with L in 120 fps frames.
pub fn ratio(clip: usize, fps: f64) -> f64 {
    let l120 = clip as f64 * 120.0 / fps;
    0.1 * (l120 / 50.0).ceil()
}

/// DCT coefficients kept for a clip of `len` frames when a full clip of `clip` keeps `l`.
pub fn coefs_for(len: usize, clip: usize, l: usize) -> usize {
    (((l * len) as f64 / clip as f64).round() as usize).clamp(1, len)
}

/// Clip boundaries `(first_frame, len)`.
pub fn clips(frames: usize, clip: usize) -> Vec<(usize, usize)> {
    (0..frames)
        .step_by(clip)
        .map(|f| (f, clip.min(frames - f)))
        .collect()
}

/// How a take is cut into clips.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClipMode {
    /// Clips of one length (the last shorter): the paper's default.
    Equal,
    /// Clip boundaries where the motion changes behaviour ([`crate::codec::segment`], the
    /// PPCA segmentation the paper takes its best results with), each segment split evenly
    /// into clips no longer than the equal length.
    Adaptive,
}

/// The clips of `input` under `mode`, none longer than `clip`.
pub fn clips_for(input: &Input<'_>, clip: usize, mode: ClipMode) -> Vec<(usize, usize)> {
    match mode {
        ClipMode::Equal => clips(input.frames, clip),
        ClipMode::Adaptive => {
            let w = input.width();
            // Each frame relative to its centroid: where the body stands is not behaviour
            // (a walk would otherwise look new at every step).
            let mut poses = Vec::with_capacity(input.data.len());
            for row in input.data.chunks_exact(w) {
                let mut c = [0f64; 3];
                for p in row.chunks_exact(3) {
                    for a in 0..3 {
                        c[a] += f64::from(p[a]);
                    }
                }
                let n = (w / 3).max(1) as f64;
                for p in row.chunks_exact(3) {
                    for a in 0..3 {
                        poses.push(f64::from(p[a]) - c[a] / n);
                    }
                }
            }
            let cuts = segment::cuts(&poses, w, &segment::Params::at(input.fps));
            segment::pieces(&cuts, input.frames, clip)
                .into_iter()
                .map(|r| (r.start, r.len()))
                .collect()
        }
    }
}

/// f32 DCT bases by (length, kept), computed once: `cos` per entry is the costliest part of
/// a decode otherwise.
#[derive(Default)]
pub struct DctTables(HashMap<(usize, usize), Vec<f32>>);

impl DctTables {
    pub fn get(&mut self, len: usize, keep: usize) -> &[f32] {
        self.0.entry((len, keep)).or_insert_with(|| {
            dct::basis(len, keep)
                .into_iter()
                .map(|v| v as f32)
                .collect()
        })
    }
}

dispatch! {
    /// Reconstruct frames `rows` of a clip of `len` frames (into `out`, `rows.len()` frames)
    /// from its dequantised coefficients (`k × lc`): `mean + (B S D̃ᵀ)ᵀ`, in f32 in a fixed
    /// order, so that encoder and decoder produce the same bits (each frame's sums are the
    /// same whichever rows are asked for).
    ///
    /// Compiled also for AVX2 and chosen at run time ([`dispatch!`]): the loops are
    /// element-wise (no sum changes its order with the vector width) and Rust never fuses a
    /// multiply and an add, so every build gives the same bits, twice as fast where AVX2 is.
    pub fn reconstruct(
        p: &Params,
        coefs: &[f32],
        d: &[f32],
        shape: (usize, usize),
        rows: Range<usize>,
        out: &mut [f32],
    ) {
        let (len, lc) = shape;
        debug_assert!(rows.end <= len);
        let w = p.width();
        let k = p.k;
        // T = B·S laid out j-major (lc × w) so the per-frame loop runs along coordinates.
        let mut t = vec![0f32; lc * w];
        for j in 0..lc {
            let row = &mut t[j * w..(j + 1) * w];
            for b in 0..k {
                let s = coefs[b * lc + j];
                if s == 0.0 {
                    continue;
                }
                for (v, bc) in row.iter_mut().zip(&p.basis[b * w..(b + 1) * w]) {
                    *v += bc * s;
                }
            }
        }
        // Four DCT rows per pass over the frame: a quarter of the loads and stores of `o`. The
        // sums are grouped the same way in encoder and decoder, so both get the same bits.
        for (f, o) in rows.zip(out.chunks_exact_mut(w)) {
            o.copy_from_slice(&p.mean);
            let dr = &d[f * lc..(f + 1) * lc];
            let mut j = 0;
            while j + 4 <= lc {
                let (d0, d1, d2, d3) = (dr[j], dr[j + 1], dr[j + 2], dr[j + 3]);
                let rows = &t[j * w..(j + 4) * w];
                let (t0, rest) = rows.split_at(w);
                let (t1, rest) = rest.split_at(w);
                let (t2, t3) = rest.split_at(w);
                for c in 0..w {
                    o[c] += t0[c] * d0 + t1[c] * d1 + t2[c] * d2 + t3[c] * d3;
                }
                j += 4;
            }
            for (jj, &dj) in dr.iter().enumerate().skip(j) {
                for (v, tv) in o.iter_mut().zip(&t[jj * w..(jj + 1) * w]) {
                    *v += tv * dj;
                }
            }
        }
    }
}

/// The per-take analysis shared by every parameter candidate: the mean, each clip's
/// leading DCT coefficients, and eigenvectors per coefficient count.
pub struct Analysis {
    pub w: usize,
    pub clip: usize,
    pub clips: Vec<(usize, usize)>,
    pub mean: Vec<f32>,
    /// Per clip, `w × lmax_i` DCT coefficients of the centred trajectories.
    pub coefs: Vec<DMatrix<f64>>,
    /// Eigenvectors (columns, largest first) and eigenvalues of `C(l)`, by `l`.
    eigen: HashMap<usize, (DMatrix<f64>, Vec<f64>)>,
    cov: std::collections::BTreeMap<usize, DMatrix<f64>>,
    pub tables: DctTables,
}

impl Analysis {
    pub fn new(input: &Input<'_>, clip: usize, lmax: usize) -> Analysis {
        Analysis::with_clips(input, clip, lmax, clips(input.frames, clip))
    }

    /// As [`Analysis::new`] with the clips given (none longer than `clip`).
    pub fn with_clips(
        input: &Input<'_>,
        clip: usize,
        lmax: usize,
        clips: Vec<(usize, usize)>,
    ) -> Analysis {
        let w = input.width();
        let frames = input.frames;
        let mut sum = vec![0f64; w];
        for row in input.data.chunks_exact(w) {
            for (m, &x) in sum.iter_mut().zip(row) {
                *m += f64::from(x);
            }
        }
        let mean: Vec<f32> = sum.iter().map(|m| (m / frames as f64) as f32).collect();
        let coefs = clips
            .iter()
            .map(|&(f0, len)| {
                let lc = coefs_for(len, clip, lmax);
                let d = dct::basis(len, lc);
                // Column j of M_i D̃_i is Σ_f d[f][j] · (x_f − mean): axpys over frames.
                let mut c = DMatrix::<f64>::zeros(w, lc);
                let mut x = vec![0f64; w];
                for f in 0..len {
                    for ((v, &raw), &m) in x.iter_mut().zip(&input.data[(f0 + f) * w..]).zip(&mean)
                    {
                        *v = f64::from(raw) - f64::from(m);
                    }
                    for j in 0..lc {
                        let dj = d[f * lc + j];
                        for (cv, xv) in c.column_mut(j).iter_mut().zip(&x) {
                            *cv += xv * dj;
                        }
                    }
                }
                c
            })
            .collect();
        Analysis {
            w,
            clip,
            clips,
            mean,
            coefs,
            eigen: HashMap::new(),
            cov: Default::default(),
            tables: DctTables::default(),
        }
    }

    pub fn lc(&self, len: usize, l: usize) -> usize {
        coefs_for(len, self.clip, l)
    }

    /// `C = Σ_i (M_i D̃_i)(M_i D̃_i)ᵀ` with `l` coefficients per full clip. Built from the
    /// largest cached `C(l₀)` with `l₀ ≤ l` by adding the columns in between: the search
    /// asks for many nearby `l`, and each full rebuild costs `w²·Σl`.
    pub fn covariance(&mut self, l: usize) -> DMatrix<f64> {
        let (l0, mut c) = match self.cov.range(..=l).next_back() {
            Some((&l0, c)) => (l0, c.clone()),
            None => (0, DMatrix::<f64>::zeros(self.w, self.w)),
        };
        for (m, &(_, len)) in self.coefs.iter().zip(&self.clips) {
            let from = if l0 == 0 {
                0
            } else {
                self.lc(len, l0).min(m.ncols())
            };
            let to = self.lc(len, l).min(m.ncols());
            if to > from {
                add_outer_products(&mut c, m.columns(from, to - from));
            }
        }
        self.cov.insert(l, c.clone());
        c
    }

    /// The `k` leading eigenvectors of `C(l)` and their eigenvalues (the energy of each
    /// coefficient row over the take); all are computed once per `l`.
    pub fn basis(&mut self, l: usize, k: usize) -> (DMatrix<f64>, Vec<f64>) {
        if !self.eigen.contains_key(&l) {
            let all = leading_eigen(&self.covariance(l), self.w);
            self.eigen.insert(l, all);
        }
        let (v, e) = &self.eigen[&l];
        (v.columns(0, k).into_owned(), e[..k].to_vec())
    }

    /// Coefficients per basis row over the take at `l` per full clip.
    pub fn coefficient_count(&self, l: usize) -> usize {
        self.clips.iter().map(|&(_, len)| self.lc(len, l)).sum()
    }
}
