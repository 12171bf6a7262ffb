//! Shared bases: transforms learned once for a library (all takes of one marker or joint
//! layout) and referenced by many takes, so that short takes do not each pay for their own.
//!
//! A basis is content addressed: its id is the BLAKE3 hash of its bytes. A container coded
//! with one records that hash in its header, and a decoder is only built when the caller
//! supplies the basis with the same hash, so a take can never be decoded with the wrong one.
//!
//! # Format
//! `"MCSB"`, version u16, kind u8, points u32, matrix count u32, then per matrix rows u32,
//! cols u32 and `rows × cols` f32 (row-major), all little-endian. Stored at f32: a basis is
//! stored once per library, so its precision costs nothing per take.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::error::{malformed, Error, Result};
use super::wire::{Reader, Writer};

const MAGIC: &[u8; 4] = b"MCSB";
const VERSION: u16 = 1;
/// Largest matrix a parser agrees to allocate (a 3000-coordinate square basis).
const MAX_ENTRIES: u64 = 9_000_000;
const MAX_MATRICES: u32 = 64;

/// What a shared basis holds; the codecs that use it say which kind they need.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BasisKind {
    /// LSDT (Hou et al. 2016): one orthogonal `J × J` matrix per coordinate x, y, z, applied
    /// as `e = B m` to the `J` points' values of that coordinate.
    Lsdt = 1,
    /// MDTT database mode (Hou et al. 2015): `K` orthonormal `3J × 3J` spatial bases, columns
    /// in order of decreasing energy; a take keeps the leading `k` columns of the one each
    /// clip chooses.
    MdttSet = 2,
}

impl BasisKind {
    pub const ALL: [BasisKind; 2] = [BasisKind::Lsdt, BasisKind::MdttSet];

    pub fn name(self) -> &'static str {
        match self {
            BasisKind::Lsdt => "lsdt",
            BasisKind::MdttSet => "mdtt-set",
        }
    }

    fn from_byte(b: u8) -> Option<BasisKind> {
        BasisKind::ALL.into_iter().find(|k| *k as u8 == b)
    }
}

impl fmt::Display for BasisKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for BasisKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        BasisKind::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                Error::Invalid(format!("unknown basis kind {s:?}; known: lsdt, mdtt-set"))
            })
    }
}

/// A dense row-major matrix of f32.
#[derive(Debug, Clone, PartialEq)]
pub struct Matrix {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f32>,
}

impl Matrix {
    pub fn row(&self, r: usize) -> &[f32] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }

    #[inline]
    pub fn at(&self, r: usize, c: usize) -> f32 {
        self.data[r * self.cols + c]
    }
}

/// A shared basis with its bytes and content hash.
#[derive(Debug, Clone, PartialEq)]
pub struct Basis {
    kind: BasisKind,
    points: usize,
    matrices: Vec<Matrix>,
    bytes: Vec<u8>,
    hash: [u8; 32],
}

impl Basis {
    /// Build a basis, checking that the matrices have the shape its kind needs.
    pub fn new(kind: BasisKind, points: usize, matrices: Vec<Matrix>) -> Result<Basis> {
        check_shape(kind, points, &matrices)?;
        let mut w = Writer::new();
        w.bytes(MAGIC);
        w.bytes(&VERSION.to_le_bytes());
        w.bytes(&[kind as u8]);
        w.u32(points as u32).u32(matrices.len() as u32);
        for m in &matrices {
            w.u32(m.rows as u32).u32(m.cols as u32);
            for &v in &m.data {
                w.f32(v);
            }
        }
        let bytes = w.0;
        let hash = *blake3::hash(&bytes).as_bytes();
        Ok(Basis {
            kind,
            points,
            matrices,
            bytes,
            hash,
        })
    }

    /// Parse stored bytes (untrusted: sizes are bounded, shapes checked).
    pub fn parse(bytes: &[u8]) -> Result<Basis> {
        let mut r = Reader::named(bytes, "basis");
        r.opening(MAGIC, VERSION, "basis")?;
        let kb = r.u8()?;
        let kind = BasisKind::from_byte(kb)
            .ok_or_else(|| Error::Unsupported(format!("basis kind {kb}")))?;
        let points = r.u32()? as usize;
        let count = r.u32()?;
        if count > MAX_MATRICES {
            return Err(Error::Limit {
                what: "basis matrices",
                actual: u64::from(count),
                limit: u64::from(MAX_MATRICES),
            });
        }
        let mut matrices = Vec::with_capacity(count as usize);
        for _ in 0..count {
            let (rows, cols) = (r.u32()? as usize, r.u32()? as usize);
            let n = rows as u64 * cols as u64;
            if n > MAX_ENTRIES {
                return Err(Error::Limit {
                    what: "basis matrix entries",
                    actual: n,
                    limit: MAX_ENTRIES,
                });
            }
            let raw = r.take(rows * cols * 4)?;
            let data = raw
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
                .collect::<Vec<_>>();
            if data.iter().any(|v| !v.is_finite()) {
                return Err(malformed("basis holds non-finite values"));
            }
            matrices.push(Matrix { rows, cols, data });
        }
        r.finish()?;
        let b = Basis::new(kind, points, matrices)?;
        debug_assert_eq!(b.bytes, bytes);
        Ok(b)
    }

    pub fn kind(&self) -> BasisKind {
        self.kind
    }
    pub fn points(&self) -> usize {
        self.points
    }
    pub fn matrices(&self) -> &[Matrix] {
        &self.matrices
    }
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }
    pub fn hash(&self) -> [u8; 32] {
        self.hash
    }
    /// The hash in hex: the basis id users see.
    pub fn id(&self) -> String {
        hex(&self.hash)
    }
}

pub fn hex(hash: &[u8; 32]) -> String {
    hash.iter().map(|b| format!("{b:02x}")).collect()
}

fn check_shape(kind: BasisKind, points: usize, ms: &[Matrix]) -> Result<()> {
    let bad = |why: String| Err(malformed(format!("{kind} basis: {why}")));
    if points == 0 {
        return bad("no points".into());
    }
    if ms.iter().any(|m| m.data.len() != m.rows * m.cols) {
        return bad("matrix data does not match its shape".into());
    }
    let side = match kind {
        BasisKind::Lsdt => {
            if ms.len() != 3 {
                return bad(format!("{} matrices, want one per coordinate", ms.len()));
            }
            points
        }
        BasisKind::MdttSet => {
            if ms.is_empty() {
                return bad("no matrices".into());
            }
            points * 3
        }
    };
    if let Some(m) = ms.iter().find(|m| m.rows != side || m.cols != side) {
        return bad(format!(
            "a {}×{} matrix for {points} points, want {side}×{side}",
            m.rows, m.cols
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn identity(n: usize) -> Matrix {
        Matrix {
            rows: n,
            cols: n,
            data: (0..n * n)
                .map(|i| if i / n == i % n { 1.0 } else { 0.0 })
                .collect(),
        }
    }

    #[test]
    fn bytes_round_trip_and_the_hash_follows_the_content() {
        let a = Basis::new(BasisKind::Lsdt, 4, vec![identity(4); 3]).unwrap();
        let b = Basis::parse(a.bytes()).unwrap();
        assert_eq!(a, b);
        let mut m = vec![identity(4); 3];
        m[2].data[5] = 0.5;
        let c = Basis::new(BasisKind::Lsdt, 4, m).unwrap();
        assert_ne!(a.hash(), c.hash());
        assert_eq!(a.id().len(), 64);
    }

    #[test]
    fn wrong_shapes_and_damaged_bytes_are_errors() {
        assert!(Basis::new(BasisKind::Lsdt, 4, vec![identity(4); 2]).is_err());
        assert!(Basis::new(BasisKind::MdttSet, 4, vec![identity(4)]).is_err());
        let a = Basis::new(BasisKind::MdttSet, 2, vec![identity(6); 2]).unwrap();
        let bytes = a.bytes();
        for cut in [0, 3, 10, bytes.len() - 1] {
            assert!(Basis::parse(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        let mut bad = bytes.to_vec();
        bad[6] = 9;
        assert!(matches!(Basis::parse(&bad), Err(Error::Unsupported(_))));
    }
}
