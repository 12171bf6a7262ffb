//! Read side: a take's metadata, and any frame range decoded from only the chunks that
//! overlap it.

use std::sync::Arc;

use super::prepared::{Prepared, ReadCaches};
use super::{blocking, Error, Result};
use crate::codec::{self, basis::hex, Header, Limits};
use crate::store::{SequenceRow, Store};

/// A range as the user states it: frame indices (end exclusive) or seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeRange {
    /// `end: None` runs to the end of the take.
    Frames {
        start: usize,
        end: Option<usize>,
    },
    Seconds {
        t0: f64,
        t1: Option<f64>,
    },
    All,
}

impl TimeRange {
    /// Frame indices `start..end` within a take of `frames` frames at `fps`. Seconds select
    /// every frame whose time `f / fps` lies in `[t0, t1)`.
    pub fn resolve(self, frames: usize, fps: f64) -> Result<(usize, usize)> {
        let (start, end) = match self {
            TimeRange::All => (0, frames),
            TimeRange::Frames { start, end } => (start, end.unwrap_or(frames)),
            TimeRange::Seconds { t0, t1 } => {
                let t1 = t1.unwrap_or(frames as f64 / fps);
                if !(t0.is_finite() && t1.is_finite() && t0 >= 0.0) {
                    return Err(Error::InvalidRequest(format!(
                        "times must be finite and ≥ 0, got {t0}..{t1}"
                    )));
                }
                let at = |t: f64| (t * fps - 1e-6).ceil().max(0.0) as usize;
                (at(t0), at(t1))
            }
        };
        if start >= end {
            return Err(Error::InvalidRequest(format!("empty range {start}..{end}")));
        }
        if end > frames {
            return Err(Error::OutOfRange(format!(
                "frames {start}..{end} are outside the take's 0..{frames}"
            )));
        }
        Ok((start, end))
    }
}

/// Decoded frames of a take.
#[derive(Debug, Clone)]
pub struct Frames {
    pub start: usize,
    pub end: usize,
    /// The names of the returned points, in order.
    pub points: Vec<String>,
    /// `(end − start) × points × 3`, NaN where the take has a gap.
    pub data: Vec<f32>,
}

pub async fn sequence(store: &Store, id: &str) -> Result<SequenceRow> {
    store
        .get(id)
        .await?
        .ok_or_else(|| Error::NotFound(format!("sequence {id}")))
}

/// The point names stored with a take: one per point, or the stored record is corrupt (an
/// error, never a default that would serve frames under no names).
pub fn point_names(row: &SequenceRow) -> Result<Vec<String>> {
    let names: Vec<String> = row
        .meta
        .get("point_names")
        .and_then(|v| serde_json::from_value(v.clone()).ok())
        .ok_or_else(|| {
            Error::Internal(format!(
                "stored take {}: meta has no point_names list",
                row.id
            ))
        })?;
    if names.len() as i64 != row.points {
        return Err(Error::Internal(format!(
            "stored take {}: {} point names for {} points",
            row.id,
            names.len(),
            row.points
        )));
    }
    Ok(names)
}

/// Decode `range` of take `id`, optionally only the named points. Chunks already decoded
/// come from `caches`; of the rest, only those overlapping the range are read and decoded.
pub async fn frames(
    store: &Store,
    caches: &ReadCaches,
    id: &str,
    range: TimeRange,
    subset: Option<&[String]>,
) -> Result<(Arc<Prepared>, Frames)> {
    let prepared = match caches.decoders.get(id) {
        // Cached state may outlive a delete made through another server sharing the
        // database: one indexed lookup keeps every answer true.
        Some(p) => {
            if !store.exists(id).await? {
                caches.forget(id);
                return Err(Error::NotFound(format!("sequence {id}")));
            }
            p
        }
        None => {
            let row = sequence(store, id).await?;
            let (header, live) = header_of(store, &row).await?;
            let shared = match &header.basis {
                Some(h) => Some(super::bases::load(store, &hex(h)).await?),
                None => None,
            };
            let p = Arc::new(blocking(move || Prepared::new(&row, header, shared)).await??);
            // A live take's index grows with every commit (here or on another server).
            if !live {
                caches.decoders.insert(p.clone());
            }
            p
        }
    };
    let (start, end) = range.resolve(prepared.frames, prepared.fps)?;
    let names = &prepared.point_names;
    let selected: Vec<usize> = match subset {
        None => (0..names.len()).collect(),
        Some(wanted) => wanted
            .iter()
            .map(|w| {
                names.iter().position(|n| n == w).ok_or_else(|| {
                    Error::InvalidRequest(format!("no point named {w:?} in this take"))
                })
            })
            .collect::<Result<_>>()?,
    };
    let wanted = prepared.header.chunks_for(start, end);
    let mut decoded: Vec<Option<Arc<Vec<f32>>>> =
        wanted.clone().map(|i| caches.chunks.get(id, i)).collect();
    let missing: Vec<usize> = wanted
        .clone()
        .filter(|&i| decoded[i - wanted.start].is_none())
        .collect();
    if let (Some(&lo), Some(&hi)) = (missing.first(), missing.last()) {
        let rows = store.chunks(id, lo as i64, hi as i64 + 1).await?;
        if rows.len() != hi + 1 - lo {
            // Deleted since its decoder was cached: forget it, and say so.
            caches.forget(id);
            sequence(store, id).await?;
            return Err(Error::Internal(format!(
                "take {id} is missing chunks {lo}..={hi}"
            )));
        }
        let p = prepared.clone();
        let wanted_missing = missing.clone();
        let fresh = blocking(move || {
            wanted_missing
                .iter()
                .map(|&i| {
                    let payload = &rows[i - lo].payload;
                    codec::decode_chunk(&p.header, p.decoder.as_ref(), i, payload).map(Arc::new)
                })
                .collect::<Result<Vec<_>, _>>()
        })
        .await??;
        for (i, chunk) in missing.into_iter().zip(fresh) {
            caches.chunks.insert(id, i, chunk.clone());
            decoded[i - wanted.start] = Some(chunk);
        }
    }
    // Copy the requested frames (and points) out of the decoded chunks.
    let all = names.len();
    let mut data = Vec::with_capacity((end - start) * selected.len() * 3);
    for (i, chunk) in wanted.clone().zip(&decoded) {
        let chunk = chunk.as_ref().expect("every wanted chunk is decoded");
        let r = prepared.header.chunks[i].frame_range();
        let (a, b) = (r.start.max(start) - r.start, r.end.min(end) - r.start);
        for frame in chunk[a * all * 3..b * all * 3].chunks_exact(all * 3) {
            if selected.len() == all {
                data.extend_from_slice(frame);
            } else {
                for &p in &selected {
                    data.extend_from_slice(&frame[p * 3..p * 3 + 3]);
                }
            }
        }
    }
    let points = selected.iter().map(|&p| names[p].clone()).collect();
    Ok((
        prepared,
        Frames {
            start,
            end,
            points,
            data,
        },
    ))
}

/// A stored take's header, and whether the take is live. A live take's stored header has
/// no chunk index (appends would otherwise rewrite it); its chunk rows are the index.
pub async fn header_of(store: &Store, row: &SequenceRow) -> Result<(Header, bool)> {
    if row.live_until.is_some() {
        let index = store.chunk_index(&row.id).await?;
        return Ok((super::streams::header_from_index(row, &index)?, true));
    }
    let (header, _) = Header::parse(&row.header, &Limits::default())
        .map_err(|e| Error::Internal(format!("stored take {}: {e}", row.id)))?;
    Ok((header, false))
}

/// Every frame of a stored take, decoded without touching the read caches (for bulk work
/// such as training, which would otherwise evict what range requests keep hot).
pub async fn whole_take(store: &Store, row: &SequenceRow) -> Result<Vec<f32>> {
    let id = &row.id;
    let (header, _) = header_of(store, row).await?;
    let shared = match &header.basis {
        Some(h) => Some(super::bases::load(store, &hex(h)).await?),
        None => None,
    };
    let rows = store.chunks(id, 0, header.chunks.len() as i64).await?;
    if rows.len() != header.chunks.len() {
        return Err(Error::NotFound(format!("sequence {id}")));
    }
    let frames = header.frames as usize;
    Ok(blocking(move || {
        let payloads: Vec<&[u8]> = rows.iter().map(|r| r.payload.as_slice()).collect();
        let d = codec::decoder(&header, shared)?;
        codec::decode_range_with(&header, d.as_ref(), &payloads, 0, frames)
    })
    .await??)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_resolve_in_frames_and_seconds() {
        assert_eq!(TimeRange::All.resolve(10, 100.0).unwrap(), (0, 10));
        let frames = |start, end| TimeRange::Frames { start, end };
        assert_eq!(frames(2, Some(5)).resolve(10, 100.0).unwrap(), (2, 5));
        assert_eq!(frames(2, None).resolve(10, 100.0).unwrap(), (2, 10));
        // Seconds 1.0..2.0 at 120 fps: frames 120..240.
        let secs = |t0, t1| TimeRange::Seconds { t0, t1 };
        assert_eq!(
            secs(1.0, Some(2.0)).resolve(1000, 120.0).unwrap(),
            (120, 240)
        );
        assert_eq!(secs(1.0, None).resolve(1000, 100.0).unwrap(), (100, 1000));
        assert!(matches!(
            frames(5, Some(5)).resolve(10, 1.0),
            Err(Error::InvalidRequest(_))
        ));
        assert!(matches!(
            frames(0, Some(11)).resolve(10, 1.0),
            Err(Error::OutOfRange(_))
        ));
        assert!(secs(f64::NAN, Some(1.0)).resolve(10, 1.0).is_err());
    }
}
