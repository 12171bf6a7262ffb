//! The learned spatial transform as the codecs apply it: one orthogonal `J × J` matrix per
//! coordinate, `e = B_d m` forward (encoder, f64) and `m = B_dᵀ e` inverse (both sides, f32,
//! one function so that an encoder's reconstruction is bit-identical to the decoder's).
//!
//! Vectors are frames as stored: `J` points interleaved x, y, z. Coefficients are laid out
//! per coordinate: `[d][r]`, `3 × J`.

use std::sync::OnceLock;

use nalgebra::DMatrix;
use wide::f32x8;

use crate::codec::basis::{Basis, BasisKind, Matrix};
use crate::codec::error::{Error, Result};

pub struct Spatial {
    j: usize,
    /// `B_d` for d = x, y, z, transposed (column `r` is basis vector `r`) and widened to
    /// f64 for the encoder's forward transform, whose inner loop then runs over rows in
    /// contiguous memory and vectorises (each row's sum keeps its order, so the
    /// coefficients are the same as with row-wise dot products). Built on first use:
    /// decoders never need it.
    bt: OnceLock<[Vec<f64>; 3]>,
    /// The same rows zero-padded to a multiple of eight and held as SIMD vectors (`wide`, so
    /// SSE or AVX as the build targets, with the scalar rounding of separate multiplies
    /// and adds): the inverse runs in whole registers with no remainder loop. Left to
    /// itself, the compiler vectorised this loop across rows, with shuffles.
    padded: [Vec<f32x8>; 3],
    /// Lane groups per padded row.
    groups: usize,
}

/// Scratch space of the inverse (see [`Spatial::scratch`]).
pub type Scratch = Vec<f32x8>;

/// A frame in the transform's layout: per coordinate, the `J` values padded to whole SIMD
/// vectors. A frame decoder keeps its loop state in this form so that prediction and
/// reconstruction run in whole registers and the frame is interleaved only once, on output
/// (scattering each coordinate into the interleaved frame cost more than the transform).
/// Every operation is lane-wise IEEE arithmetic in the order the interleaved code uses, so
/// results are bit-identical to it.
#[derive(Clone)]
pub struct Planar {
    j: usize,
    groups: usize,
    /// `[d][group]`; padding lanes stay zero.
    v: Vec<f32x8>,
}

impl Planar {
    pub fn clear(&mut self) {
        self.v.fill(f32x8::ZERO);
    }

    pub fn copy_from(&mut self, other: &Planar) {
        self.v.copy_from_slice(&other.v);
    }

    /// `2a − b`: the order-2 prediction.
    pub fn extrapolate(&mut self, a: &Planar, b: &Planar) {
        let two = f32x8::splat(2.0);
        for ((o, &a), &b) in self.v.iter_mut().zip(&a.v).zip(&b.v) {
            *o = two * a - b;
        }
    }

    /// Add `x` to sample `i` of the interleaved frame (`3 · point + axis`).
    #[inline]
    pub fn add(&mut self, i: usize, x: f32) {
        let (p, d) = (i / 3, i % 3);
        self.v[d * self.groups + p / 8].as_mut_array()[p % 8] += x;
    }

    /// Write the frame interleaved (`J` points × x, y, z) into `out`.
    pub fn write_interleaved(&self, out: &mut [f32]) {
        let g = self.groups;
        let (x, rest) = self.v.split_at(g);
        let (y, z) = rest.split_at(g);
        let out = &mut out[..self.j * 3];
        let mut groups = out.chunks_exact_mut(24);
        // Whole groups of eight points as fixed-size arrays: straight-line stores.
        for (c, o) in (&mut groups).enumerate() {
            let o: &mut [f32; 24] = o.try_into().expect("24 values");
            let (x, y, z) = (x[c].as_array(), y[c].as_array(), z[c].as_array());
            for k in 0..8 {
                o[3 * k] = x[k];
                o[3 * k + 1] = y[k];
                o[3 * k + 2] = z[k];
            }
        }
        let rest = groups.into_remainder();
        if !rest.is_empty() {
            let c = self.j / 8;
            let (x, y, z) = (x[c].as_array(), y[c].as_array(), z[c].as_array());
            for (k, o) in rest.chunks_exact_mut(3).enumerate() {
                o[0] = x[k];
                o[1] = y[k];
                o[2] = z[k];
            }
        }
    }
}

impl Spatial {
    pub fn new(basis: &Basis) -> Result<Spatial> {
        if basis.kind() != BasisKind::Lsdt {
            return Err(Error::Basis(format!(
                "LSDT codecs need an lsdt basis, got {}",
                basis.kind()
            )));
        }
        let m = basis.matrices();
        let j = basis.points();
        let groups = j.div_ceil(8);
        let pad = |data: &[f32]| {
            let mut p = Vec::with_capacity(j * groups);
            for row in data.chunks_exact(j) {
                for c in 0..groups {
                    let mut lanes = [0f32; 8];
                    for (k, l) in lanes.iter_mut().enumerate() {
                        *l = row.get(c * 8 + k).copied().unwrap_or(0.0);
                    }
                    p.push(f32x8::new(lanes));
                }
            }
            p
        };
        Ok(Spatial {
            j,
            bt: OnceLock::new(),
            padded: [pad(&m[0].data), pad(&m[1].data), pad(&m[2].data)],
            groups,
        })
    }

    pub fn points(&self) -> usize {
        self.j
    }

    /// Scratch space for [`Spatial::inverse_add`].
    pub fn scratch(&self) -> Scratch {
        vec![f32x8::ZERO; self.groups]
    }

    /// `B_dᵀ` in f64, from the padded rows (see `bt`).
    fn transposed(&self) -> &[Vec<f64>; 3] {
        self.bt.get_or_init(|| {
            let (j, g) = (self.j, self.groups);
            [0, 1, 2].map(|d| {
                let b = &self.padded[d];
                (0..j * j)
                    .map(|i| {
                        let (p, r) = (i / j, i % j);
                        f64::from(b[r * g + p / 8].as_array()[p % 8])
                    })
                    .collect()
            })
        })
    }

    /// A zero frame in the layout of [`Spatial::inverse_add_planar`].
    pub fn planar(&self) -> Planar {
        Planar {
            j: self.j,
            groups: self.groups,
            v: vec![f32x8::ZERO; 3 * self.groups],
        }
    }

    /// The transform `codec` codes a take of `points` points with: the shared basis must be
    /// there, of kind lsdt, and of the take's size.
    pub fn for_take(shared: Option<&Basis>, points: usize, codec: &str) -> Result<Spatial> {
        let basis =
            shared.ok_or_else(|| Error::Basis(format!("{codec} needs a shared lsdt basis")))?;
        let s = Spatial::new(basis)?;
        if s.j != points {
            return Err(Error::Basis(format!(
                "basis for {} points, take has {points}",
                s.j
            )));
        }
        Ok(s)
    }

    /// `e[d·J + r] = Σ_j B_d[r][j] · x[3j + d]`.
    pub fn forward(&self, x: &[f64], e: &mut [f64]) {
        let j = self.j;
        for d in 0..3 {
            let sums = &mut e[d * j..(d + 1) * j];
            sums.fill(0.0);
            for (p, column) in self.transposed()[d].chunks_exact(j).enumerate() {
                let v = x[p * 3 + d];
                for (s, &b) in sums.iter_mut().zip(column) {
                    *s += b * v;
                }
            }
        }
    }

    /// `out[3j + d] += Σ_r B_d[r][j] · q[d·J + r] · step` over the non-zero `q` only (after
    /// thresholding most are zero). Rows are summed in `scratch` (from [`Spatial::scratch`])
    /// in ascending order and then interleaved into `out`; the order of the additions is
    /// fixed, so the encoder's reconstruction and every decoder's are bit-identical.
    pub fn inverse_add(&self, q: &[i32], step: f32, scratch: &mut [f32x8], out: &mut [f32]) {
        let j = self.j;
        let mut rows = Vec::with_capacity(j);
        for d in 0..3 {
            let qd = &q[d * j..(d + 1) * j];
            rows.clear();
            rows.extend((0..j as u16).filter(|&r| qd[usize::from(r)] != 0));
            if rows.is_empty() {
                continue;
            }
            let acc = self.accumulate(d, &rows, qd, step, scratch);
            let out = &mut out[d..];
            for (g, v) in acc.iter().enumerate() {
                for (k, &x) in v.as_array().iter().enumerate().take(j - g * 8) {
                    out[(g * 8 + k) * 3] += x;
                }
            }
        }
    }

    /// [`Spatial::inverse_add`] for coordinate `d` into a [`Planar`] frame, given the
    /// non-zero rows (ascending) that a decoder lists as it reads them — no branch per
    /// coefficient; `q` is the coordinate's `J` coefficients. The same sums, added lane-wise.
    pub fn inverse_add_planar(
        &self,
        d: usize,
        rows: &[u16],
        q: &[i32],
        step: f32,
        scratch: &mut [f32x8],
        out: &mut Planar,
    ) {
        if rows.is_empty() {
            return;
        }
        let acc = self.accumulate(d, rows, q, step, scratch);
        let g = self.groups;
        for (o, &a) in out.v[d * g..(d + 1) * g].iter_mut().zip(acc.iter()) {
            *o += a;
        }
    }

    /// `Σ_r B_d[r] · q[r] · step` over `rows`, from zero, in row order.
    #[inline]
    fn accumulate<'s>(
        &self,
        d: usize,
        rows: &[u16],
        q: &[i32],
        step: f32,
        scratch: &'s mut [f32x8],
    ) -> &'s [f32x8] {
        let g = self.groups;
        let b = &self.padded[d];
        let acc = &mut scratch[..g];
        // Skeletons and marker sets up to 64 points: the sums stay in registers for the
        // whole frame (through memory, each row's adds wait for the last row's stores).
        match g {
            1 => in_registers::<1>(b, rows, q, step, acc),
            2 => in_registers::<2>(b, rows, q, step, acc),
            3 => in_registers::<3>(b, rows, q, step, acc),
            4 => in_registers::<4>(b, rows, q, step, acc),
            5 => in_registers::<5>(b, rows, q, step, acc),
            6 => in_registers::<6>(b, rows, q, step, acc),
            7 => in_registers::<7>(b, rows, q, step, acc),
            8 => in_registers::<8>(b, rows, q, step, acc),
            _ => {
                acc.fill(f32x8::ZERO);
                for &r in rows {
                    let r = usize::from(r);
                    let a = f32x8::splat(q[r] as f32 * step);
                    for (o, &bv) in acc.iter_mut().zip(&b[r * g..(r + 1) * g]) {
                        *o += a * bv;
                    }
                }
            }
        }
        acc
    }
}

/// [`Spatial::accumulate`] for `G` lane groups, with the sums in a local array (the same
/// operations in the same order, so the same bits).
#[inline(always)]
fn in_registers<const G: usize>(
    b: &[f32x8],
    rows: &[u16],
    q: &[i32],
    step: f32,
    out: &mut [f32x8],
) {
    let mut acc = [f32x8::ZERO; G];
    for &r in rows {
        let r = usize::from(r);
        let a = f32x8::splat(q[r] as f32 * step);
        let row: &[f32x8; G] = b[r * G..(r + 1) * G].try_into().expect("G groups per row");
        for (o, &bv) in acc.iter_mut().zip(row) {
            *o += a * bv;
        }
    }
    out.copy_from_slice(&acc);
}

/// Build an LSDT [`Basis`] from trained per-coordinate matrices (`B` applied as `B m`).
pub fn basis_from(trained: [&DMatrix<f64>; 3]) -> Result<Basis> {
    let j = trained[0].nrows();
    let matrices = trained
        .iter()
        .map(|b| Matrix {
            rows: j,
            cols: j,
            data: (0..j * j).map(|i| b[(i / j, i % j)] as f32).collect(),
        })
        .collect();
    Basis::new(BasisKind::Lsdt, j, matrices)
}

/// How [`dct_basis`] was made, as a stored basis records it.
pub const DCT_PROVENANCE: &str = "DCT-II, untrained: no lsdt basis was trained for this layout";

/// [`dct_basis`] and its provenance: what the LSDT codecs stream with before a basis is
/// trained for the layout ([`crate::codec::stream::Streaming::untrained_basis`]).
pub fn untrained(points: usize) -> (Basis, &'static str) {
    (dct_basis(points), DCT_PROVENANCE)
}

/// The DCT as an LSDT basis: what live streams code with before a basis is trained for
/// their layout, and the paper's starting point.
pub fn dct_basis(j: usize) -> Basis {
    let d = crate::codec::dct::basis(j, j);
    let b = DMatrix::from_fn(j, j, |r, c| d[c * j + r]);
    basis_from([&b, &b, &b]).expect("square matrices of the right size")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_undoes_forward() {
        let j = 7;
        let s = Spatial::new(&dct_basis(j)).unwrap();
        let x: Vec<f64> = (0..j * 3).map(|i| (i as f64 * 0.7).sin() * 50.0).collect();
        let mut e = vec![0.0; j * 3];
        s.forward(&x, &mut e);
        // Quantise with a fine step and invert.
        let step = 1e-3f32;
        let q: Vec<i32> = e
            .iter()
            .map(|v| (v / f64::from(step)).round() as i32)
            .collect();
        let mut out = vec![0f32; j * 3];
        s.inverse_add(&q, step, &mut s.scratch(), &mut out);
        for (a, b) in x.iter().zip(&out) {
            assert!((a - f64::from(*b)).abs() < 1e-2, "{a} vs {b}");
        }
    }

    #[test]
    fn planar_reconstruction_is_bit_identical_to_interleaved() {
        // Lane groups in registers (1..=8) and the generic path (9), whole and partial.
        for j in [3, 7, 8, 16, 38, 70] {
            let s = Spatial::new(&dct_basis(j)).unwrap();
            let prediction: Vec<f32> = (0..j * 3).map(|i| (i as f32 * 1.3).cos() * 40.0).collect();
            let q: Vec<i32> = (0..j * 3)
                .map(|i| {
                    if i % 3 == 0 {
                        0
                    } else {
                        (i as i32 * 7) % 23 - 11
                    }
                })
                .collect();
            let step = 0.37f32;
            let mut interleaved = prediction.clone();
            s.inverse_add(&q, step, &mut s.scratch(), &mut interleaved);
            let mut planar = s.planar();
            for (i, &v) in prediction.iter().enumerate() {
                planar.add(i, v);
            }
            let mut scratch = s.scratch();
            for d in 0..3 {
                let qd = &q[d * j..(d + 1) * j];
                let rows: Vec<u16> = (0..j as u16).filter(|&r| qd[usize::from(r)] != 0).collect();
                s.inverse_add_planar(d, &rows, qd, step, &mut scratch, &mut planar);
            }
            let mut out = vec![f32::NAN; j * 3];
            planar.write_interleaved(&mut out);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&out), bits(&interleaved), "{j} points");
        }
    }
}
