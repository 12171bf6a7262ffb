//! Read side: a take's metadata, and any frame range decoded from only the chunks that
//! overlap it.

use std::sync::Arc;

use super::prepared::{DecoderCache, Prepared};
use super::{blocking, Error, Result};
use crate::codec;
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

/// The point names stored with a take.
pub fn point_names(row: &SequenceRow) -> Vec<String> {
    row.meta
        .get("point_names")
        .and_then(|v| serde_json::from_value(v.clone()).ok())
        .unwrap_or_default()
}

/// Decode `range` of take `id`, optionally only the named points. Only the chunks that
/// overlap the range are read; the take's decoder comes from `cache` when it is there.
pub async fn frames(
    store: &Store,
    cache: &DecoderCache,
    id: &str,
    range: TimeRange,
    subset: Option<&[String]>,
) -> Result<(Arc<Prepared>, Frames)> {
    let prepared = match cache.get(id) {
        Some(p) => p,
        None => {
            let row = sequence(store, id).await?;
            let p = Arc::new(
                blocking(move || Prepared::new(&row))
                    .await?
                    .map_err(|e| Error::Internal(format!("stored take {id}: {e}")))?,
            );
            cache.insert(p.clone());
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
    let chunks = store
        .chunks(id, wanted.start as i64, wanted.end as i64)
        .await?;
    if chunks.len() != wanted.len() {
        // Deleted since its decoder was cached: forget it, and say so.
        cache.remove(id);
        sequence(store, id).await?;
        return Err(Error::Internal(format!(
            "take {id} is missing chunks {wanted:?}"
        )));
    }
    let all_points = names.len();
    let p = prepared.clone();
    let data = blocking(move || {
        let payloads: Vec<&[u8]> = chunks.iter().map(|c| c.payload.as_slice()).collect();
        codec::decode_range_with(&p.header, p.decoder.as_ref(), &payloads, start, end)
    })
    .await??;
    let data = if selected.len() == all_points {
        data
    } else {
        data.chunks_exact(all_points * 3)
            .flat_map(|frame| {
                selected
                    .iter()
                    .flat_map(move |&p| frame[p * 3..p * 3 + 3].iter().copied())
            })
            .collect()
    };
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
