//! Read side: a take's metadata and error series, and the readers range answers decode
//! with ([`super::answer`]), kept per take.

use super::take::Take;
use super::{blocking, Error, Result};
use crate::codec::container::ChunkMeta;
use crate::codec::{self, basis::hex, DecodeLimits, Header, Reader, Shared, Stored};
use crate::motion::rate;
use crate::store::{ChunkEntry, Store, TakeRow};

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
    /// every frame whose time `f / rate` lies in `[t0, t1)`, `rate` the rate `fps` was
    /// written for ([`rate::nominal`]: a BVH's `Frame Time: 0.0333333` is 30 fps, so a
    /// second holds 30 frames, not 31). Errors speak in the units the range was given in.
    pub fn resolve(self, frames: usize, fps: f64) -> Result<(usize, usize)> {
        let (start, end) = match self {
            TimeRange::All => (0, frames),
            TimeRange::Frames { start, end } => (start, end.unwrap_or(frames)),
            TimeRange::Seconds { t0, t1 } => return seconds(t0, t1, frames, fps),
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

impl TimeRange {
    /// The seconds from frame `start` (of a take at `fps`) to the range's end: to `t1` when
    /// the range was given in seconds, else to frame `end`. The frames of a resampled
    /// answer are those before it.
    pub fn seconds_from(self, start: usize, end: usize, fps: f64) -> f64 {
        let rate = rate::nominal(fps);
        match self {
            TimeRange::Seconds { t1: Some(t1), .. } => t1 - start as f64 / rate,
            _ => (end - start) as f64 / rate,
        }
    }
}

/// [`TimeRange::resolve`] of `t0..t1` seconds.
fn seconds(t0: f64, t1: Option<f64>, frames: usize, fps: f64) -> Result<(usize, usize)> {
    let rate = rate::nominal(fps);
    let length = frames as f64 / rate;
    let t1 = t1.unwrap_or(length);
    if !(t0.is_finite() && t1.is_finite() && t0 >= 0.0) {
        return Err(Error::InvalidRequest(format!(
            "times must be finite and ≥ 0, got t0={t0} t1={t1}"
        )));
    }
    let (start, end) = (
        rate::first_frame_from(t0, fps),
        rate::first_frame_from(t1, fps),
    );
    let lasts = || format!("the take lasts {length:.6} s ({frames} frames at {rate} fps)");
    if end > frames as f64 {
        return Err(Error::OutOfRange(format!(
            "t1={t1} s is past the take's end: {}",
            lasts()
        )));
    }
    if start >= end {
        return Err(Error::InvalidRequest(format!(
            "t0={t0} s to t1={t1} s holds no frame: {}",
            lasts()
        )));
    }
    Ok((start as usize, end as usize))
}

/// The take stored under `id`, parsed.
pub async fn take(store: &Store, id: &str) -> Result<Take> {
    let row = store
        .get(id)
        .await?
        .ok_or_else(|| Error::NotFound(format!("take {id}")))?;
    parse(store, row).await
}

/// A stored row parsed, with the skeleton it names (which names its points).
pub async fn parse(store: &Store, row: TakeRow) -> Result<Take> {
    let rig = match &row.skeleton_id {
        Some(id) => Some(super::skeletons::load(store, id).await?),
        None => None,
    };
    Take::from_row(row, rig.as_deref())
}

/// A take's error second by second, with its bound: what a viewer charts.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TakeErrors {
    pub id: String,
    pub fps: f64,
    pub frames: usize,
    pub max_bound_mm: f64,
    pub mean_bound_mm: Option<f64>,
    #[serde(flatten)]
    pub series: crate::motion::metrics::ErrorSeries,
}

/// The error series measured when take `id` was stored; `Unsatisfiable` for takes that
/// have none (stored before series were measured, imported, or streamed live).
pub async fn errors(store: &Store, id: &str) -> Result<TakeErrors> {
    let take = take(store, id).await?;
    let bytes = store.error_series(id).await?.ok_or_else(|| {
        Error::Unsatisfiable(format!(
            "take {id} has no error series: it was streamed live, imported, or stored before \
             series were measured"
        ))
    })?;
    let series = crate::motion::metrics::ErrorSeries::from_bytes(&bytes)
        .map_err(|e| Error::Corrupt(format!("take {id}: {e}")))?;
    Ok(TakeErrors {
        id: take.id,
        fps: take.fps,
        frames: take.frames,
        max_bound_mm: take.bound.max_mm(),
        mean_bound_mm: take.bound.mean_mm(),
        series,
    })
}

/// What a header names (a shared basis, a skeleton), loaded by id.
pub async fn shared(store: &Store, header: &Header) -> Result<Shared> {
    let basis = match &header.basis {
        Some(h) => Some(super::bases::load(store, &hex(h)).await?),
        None => None,
    };
    let rig = match &header.rig {
        Some(h) => Some(super::skeletons::load(store, &hex(h)).await?),
        None => None,
    };
    Ok(Shared { basis, rig })
}

/// A stored take's header, and whether the take is live. A live take's stored header has
/// no chunk index (appends would otherwise rewrite it); its chunk rows are the index.
pub async fn header_of(store: &Store, take: &Take) -> Result<(Header, bool)> {
    if take.is_live() {
        let index = store.chunk_index(&take.id).await?;
        return Ok((header_from_index(take, &index)?, true));
    }
    Ok((stored_header(take)?, false))
}

/// The header stored with a closed take (chunk index included).
pub fn stored_header(take: &Take) -> Result<Header> {
    Header::parse(&take.header, &DecodeLimits::default())
        .map(|(h, _)| h)
        .map_err(|e| Error::Corrupt(format!("stored take {}: header: {e}", take.id)))
}

/// A live take's header with the chunk rows as its index (and frames), checked as any
/// stored header is.
pub(crate) fn header_from_index(take: &Take, index: &[ChunkEntry]) -> Result<Header> {
    let id = &take.id;
    let corrupt = |e: &dyn std::fmt::Display| Error::Corrupt(format!("stored take {id}: {e}"));
    let (mut header, _) =
        Header::parse(&take.header, &codec::DecodeLimits::default()).map_err(|e| corrupt(&e))?;
    let mut chunks = Vec::with_capacity(index.len());
    for c in index {
        let as_u32 = |v: i64| u32::try_from(v).map_err(|_| corrupt(&format!("chunk {c:?}")));
        chunks.push(ChunkMeta {
            first_frame: as_u32(c.first_frame)?,
            frames: as_u32(c.frames)?,
            len: as_u32(c.len)?,
            crc32c: c.crc32c,
        });
    }
    header.frames = chunks.iter().map(|c| c.frames).sum();
    header.chunks = chunks;
    // Round-trip through the parser: the index must tile the frames in order.
    Header::parse(&header.to_bytes(), &codec::DecodeLimits::default())
        .map(|(h, _)| h)
        .map_err(|e| corrupt(&e))
}

/// Every frame of a stored take, decoded without touching the read caches (for bulk work
/// such as training, which would otherwise evict what range requests keep hot).
pub async fn whole_take(store: &Store, take: &Take) -> Result<Vec<f32>> {
    let id = &take.id;
    let (header, _) = header_of(store, take).await?;
    let shared = shared(store, &header).await?;
    let rows = store.chunks(id, 0, header.chunks.len() as i64).await?;
    if rows.len() != header.chunks.len() {
        return Err(Error::NotFound(format!("take {id}")));
    }
    Ok(blocking(move || {
        Reader::new(header, shared)?.read_all(&Stored::new(0, rows.iter().map(|r| &r.payload[..])))
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
        // A BVH's printed 30 fps: a second is 30 frames; past the end is said in seconds.
        let bvh = 1.0 / 0.0333333;
        assert_eq!(secs(0.0, Some(1.0)).resolve(100, bvh).unwrap(), (0, 30));
        assert_eq!(secs(3.0, None).resolve(100, bvh).unwrap(), (90, 100));
        let Err(Error::OutOfRange(e)) = secs(0.0, Some(4.0)).resolve(100, bvh) else {
            panic!("4 s of a 3.33 s take");
        };
        assert!(e.contains("t1=4 s") && e.contains("3.333333 s"), "{e}");
    }
}
