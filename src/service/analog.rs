//! What a take keeps beside its points: analog channels (coded with the analog codecs,
//! chosen here like the point codecs are), the file's parameter section, and the C3D file
//! they make together again.

use std::collections::BTreeMap;
use std::str::FromStr;
use std::sync::Arc;

use serde::Serialize;

use super::budget::{Budget, Holder, Reservation};
use super::fetch::TimeRange;
use super::take::{AnalogMeta, ChannelMeta, Take};
use super::{blocking, Error, Result};
use crate::codec::analog::{self, Decoder};
use crate::codec::{CodecId, Container, Header};
use crate::limits::Limits;
use crate::motion::analog::Analog;
use crate::motion::formats::c3d::params::Parameters;
use crate::store::{AnalogRows, ChunkRow, ParametersRow, Store};

/// The format tag of stored parameters: a C3D parameter section in Intel order, zstd.
pub const PARAMETERS_FORMAT: &str = "c3d-section+zstd";
/// Largest decompressed parameter section: 255 blocks of 512 bytes is what C3D can hold.
const MAX_SECTION: usize = 255 * 512;

/// Analog bounds as a request states them, in each channel's own unit: one for every
/// channel (`0.5`), per label (`Fz1=0.5,EMG1=1e-6`), or both (`*=0.01,Fz1=0.5`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AnalogBounds {
    pub all: Option<f64>,
    pub by_label: BTreeMap<String, f64>,
}

impl AnalogBounds {
    pub fn is_empty(&self) -> bool {
        self.all.is_none() && self.by_label.is_empty()
    }

    /// Per channel of `analog`, its bound (`None`: lossless); `InvalidRequest` naming a
    /// label the take does not have.
    pub fn per_channel(&self, analog: &Analog) -> Result<Vec<Option<f64>>> {
        for label in self.by_label.keys() {
            if !analog.channels.iter().any(|c| &c.label == label) {
                return Err(Error::InvalidRequest(format!(
                    "analog_bound names {label:?}, which is not an analog channel of the take"
                )));
            }
        }
        Ok(analog
            .channels
            .iter()
            .map(|c| self.by_label.get(&c.label).copied().or(self.all))
            .collect())
    }
}

impl FromStr for AnalogBounds {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let mut b = AnalogBounds::default();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (label, value) = match item.rsplit_once('=') {
                Some((l, v)) => (Some(l.trim()), v),
                None => (None, item),
            };
            let v: f64 = value
                .trim()
                .parse()
                .map_err(|_| format!("analog bound {value:?} is not a number"))?;
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("analog bound {v} must be a positive number"));
            }
            match label {
                None | Some("*") => b.all = Some(v),
                Some(l) => {
                    b.by_label.insert(l.to_string(), v);
                }
            }
        }
        Ok(b)
    }
}

/// Analog channels coded for storage: the winner and its metadata.
pub struct Coded {
    pub container: Container,
    pub meta: AnalogMeta,
}

/// Code `analog` (of a take at `fps` whose point chunks cover `chunk_frames` frames each):
/// losslessly, and within `bounds` when the request states any; the smaller wins.
pub async fn code(
    analog: Arc<Analog>,
    fps: f64,
    chunk_frames: Vec<usize>,
    bounds: &AnalogBounds,
) -> Result<Coded> {
    let per_channel = bounds.per_channel(&analog)?;
    let chunk_frames = analog::chunk_frames(&chunk_frames, analog.per_frame);
    let bounded = per_channel.iter().any(Option::is_some);
    blocking(move || -> Result<Coded> {
        let t0 = std::time::Instant::now();
        let mut tried = Vec::new();
        let mut best: Option<analog::Encoded> = None;
        let candidates: Vec<Vec<Option<f64>>> = if bounded {
            vec![Vec::new(), per_channel.clone()]
        } else {
            vec![Vec::new()]
        };
        for b in candidates {
            let e = analog::encode(&analog, fps, &chunk_frames, &b)?;
            let size = e.container.stored_bytes() as u64;
            tried.push((e.container.header.codec, size));
            if best
                .as_ref()
                .is_none_or(|w| size < w.container.stored_bytes() as u64)
            {
                best = Some(e);
            }
        }
        let e = best.expect("one candidate at least");
        let codec = e.container.header.codec;
        let stored = e.container.stored_bytes() as u64;
        let raw = analog.raw_bytes() as u64;
        let reason = match (bounded, codec) {
            (false, _) => format!(
                "{codec}: no analog bound was stated, so every value is kept exactly as the \
                 file stored it"
            ),
            (true, CodecId::AnalogBounded) => format!(
                "{codec} ({stored} bytes) is smaller than analog-lossless ({} bytes) and keeps \
                 every channel within its bound",
                tried[0].1
            ),
            (true, _) => format!(
                "{codec}: the bounds are below one stored step of every bounded channel, so \
                 coding within them is coding exactly"
            ),
        };
        let channels = analog
            .channels
            .iter()
            .enumerate()
            .map(|(c, ch)| ChannelMeta {
                label: ch.label.clone(),
                unit: ch.unit.clone(),
                description: ch.description.clone(),
                bound: if codec == CodecId::AnalogBounded {
                    per_channel[c]
                } else {
                    None
                },
                max_error: e.max_error[c],
            })
            .collect();
        Ok(Coded {
            meta: AnalogMeta {
                codec,
                rate: analog.rate(fps),
                samples_per_frame: analog.per_frame,
                channels,
                raw_bytes: raw,
                stored_bytes: stored,
                ratio: raw as f64 / stored.max(1) as f64,
                tried,
                reason,
                encode_ms: t0.elapsed().as_secs_f64() * 1e3,
            },
            container: e.container,
        })
    })
    .await?
}

/// The rows a coded analog container is stored as.
pub fn rows(c: &Container, meta: &AnalogMeta) -> AnalogRows {
    AnalogRows {
        header: c.header.to_bytes(),
        raw_bytes: meta.raw_bytes as i64,
        stored_bytes: meta.stored_bytes as i64,
        chunks: super::take::chunk_rows(c),
    }
}

/// Parameters as stored: their Intel section, compressed.
pub fn parameters_row(p: &Parameters) -> Result<ParametersRow> {
    let section = p
        .to_section()
        .map_err(|e| Error::Unsatisfiable(format!("the file's parameters: {e}")))?;
    let payload =
        zstd::bulk::compress(&section, 19).map_err(|e| Error::Internal(format!("zstd: {e}")))?;
    Ok(ParametersRow {
        format: PARAMETERS_FORMAT.into(),
        payload,
    })
}

/// Stored parameters parsed; `Corrupt` if they do not.
pub fn parameters_of(id: &str, row: &ParametersRow) -> Result<Parameters> {
    let corrupt = |what: String| Error::Corrupt(format!("parameters of take {id}: {what}"));
    if row.format != PARAMETERS_FORMAT {
        return Err(corrupt(format!("unknown format {:?}", row.format)));
    }
    let section =
        zstd::bulk::decompress(&row.payload, MAX_SECTION).map_err(|e| corrupt(e.to_string()))?;
    Parameters::from_section(&section).map_err(|e| corrupt(e.to_string()))
}

/// Take `id`'s stored parameters, if its file had any.
pub async fn parameters(store: &Store, id: &str) -> Result<Option<Parameters>> {
    match store.parameters(id).await? {
        Some(row) => Ok(Some(parameters_of(id, &row)?)),
        None => Ok(None),
    }
}

/// The decoder of take `id`'s analog channels; `None` if it has none.
pub async fn decoder(store: &Store, id: &str) -> Result<Option<Decoder>> {
    let Some(rows) = store.analog(id).await? else {
        return Ok(None);
    };
    let (header, _) = Header::parse(&rows.header, &crate::codec::DecodeLimits::default())
        .map_err(|e| Error::Corrupt(format!("analog header of take {id}: {e}")))?;
    Ok(Some(Decoder::new(header).map_err(|e| {
        Error::Corrupt(format!("analog header of take {id}: {e}"))
    })?))
}

/// Analog of point frames `start..end` of take `id`: only the chunks that cover them are
/// read and decoded.
pub async fn range_of(
    store: &Store,
    id: &str,
    decoder: &Decoder,
    start: usize,
    end: usize,
) -> Result<Analog> {
    let chunks = decoder.header().chunks_for(start, end);
    let rows: Vec<ChunkRow> = store
        .analog_chunks(id, chunks.start as i64, chunks.end as i64)
        .await?;
    if rows.len() != chunks.len() {
        return Err(Error::Corrupt(format!(
            "take {id}: {} of analog chunks {chunks:?} are stored",
            rows.len()
        )));
    }
    let d = decoder.clone();
    blocking(move || -> Result<Analog> {
        let first_frame = d.header().chunks[chunks.start].first_frame as usize;
        let samples = d.decode_chunks(chunks.start, rows.iter().map(|r| r.payload.as_slice()))?;
        let whole = d.analog(samples)?;
        Ok(whole.slice_frames(start - first_frame, end - first_frame))
    })
    .await?
}

/// Values of `channels` of `analog`, in their units, `rows × channels`.
pub fn values_of(analog: &Analog, channels: &[usize]) -> Vec<f64> {
    let mut out = Vec::with_capacity(analog.rows() * channels.len());
    for r in 0..analog.rows() {
        out.extend(channels.iter().map(|&c| analog.value(r, c)));
    }
    out
}

/// What every read of a take's analog starts from: the take, its analog decoder (`None`
/// without analog channels) and the range resolved against the take's frames.
struct Opened {
    take: Take,
    decoder: Option<Decoder>,
    start: usize,
    end: usize,
}

async fn open(store: &Store, id: &str, range: TimeRange) -> Result<Opened> {
    let take = super::fetch::take(store, id).await?;
    let (start, end) = range.resolve(take.frames, take.fps)?;
    let decoder = decoder(store, id).await?;
    Ok(Opened {
        take,
        decoder,
        start,
        end,
    })
}

/// An analog answer: the values of some channels over a range, in their units.
pub struct AnalogAnswer {
    pub start_frame: usize,
    pub frames: usize,
    pub rate: f64,
    /// Seconds of the first sample from the take's start.
    pub t0: f64,
    pub columns: Vec<crate::motion::formats::columns::Column>,
    /// `rows × columns`.
    pub values: Vec<f64>,
    /// What the answer holds from the server's answer budget, until it is written.
    pub reservation: Reservation,
}

/// The analog channels `labels` (all when empty) of frames `range` of take `id`, in their
/// units. Only the chunks over the range are decoded; the answer is checked against
/// [`Limits::answer_samples`] and reserved from the answer budget before anything is read.
pub async fn answer(
    store: &Store,
    budget: &Arc<Budget>,
    holder: Holder,
    limits: &Limits,
    id: &str,
    range: TimeRange,
    labels: &[String],
) -> Result<AnalogAnswer> {
    let Opened {
        take,
        decoder: d,
        start,
        end,
    } = open(store, id, range).await?;
    let d = d.ok_or_else(|| Error::Unsatisfiable(format!("take {id} has no analog channels")))?;
    let layout = d.layout();
    let per_frame = layout.per_frame;
    let channels = labels_to_indices(&layout.channels, labels)?;
    let rows = (end - start) * per_frame;
    let values = rows as u64 * channels.len() as u64;
    if values > limits.answer_samples.saturating_mul(3) {
        return Err(Error::InvalidRequest(format!(
            "{values} analog values is over the limit of {} in one answer; ask for fewer \
             channels or a shorter range",
            limits.answer_samples.saturating_mul(3)
        )));
    }
    // Decoded chunks (4-byte values of every channel), then the values answered (8 bytes)
    // and their text (JSON and CSV take up to ~25 bytes a value).
    let chunk_rows: u64 = d.header().chunks[d.header().chunks_for(start, end)]
        .iter()
        .map(|c| u64::from(c.frames) * per_frame as u64)
        .sum();
    let bound = chunk_rows * layout.channels.len() as u64 * 4 * 2 + values * (8 + 25);
    let mut reservation = budget.reservation(holder);
    reservation
        .grow_to(bound)
        .map_err(|r| Error::Busy(format!("{}; retry shortly", r.reason("analog answers"))))?;
    let analog = range_of(store, id, &d, start, end).await?;
    let columns = channels
        .iter()
        .map(|&c| crate::motion::formats::columns::Column {
            label: layout.channels[c].label.clone(),
            unit: layout.channels[c].unit.clone(),
        })
        .collect();
    let values = blocking(move || values_of(&analog, &channels)).await?;
    Ok(AnalogAnswer {
        start_frame: start,
        frames: end - start,
        rate: take.fps * per_frame as f64,
        t0: start as f64 / crate::motion::rate::nominal(take.fps),
        columns,
        values,
        reservation,
    })
}

fn labels_to_indices(
    channels: &[crate::motion::analog::Channel],
    labels: &[String],
) -> Result<Vec<usize>> {
    if labels.is_empty() {
        return Ok((0..channels.len()).collect());
    }
    labels
        .iter()
        .map(|l| {
            channels.iter().position(|c| &c.label == l).ok_or_else(|| {
                Error::InvalidRequest(format!("{l:?} is not an analog channel of the take"))
            })
        })
        .collect()
}

/// A force plate as `FORCE_PLATFORM` describes it: its type, the analog channels it
/// feeds (1-based, as the file numbers them), its corners and origin (in the file's point
/// units) and its calibration matrix, where the file has one.
#[derive(Debug, Clone, Serialize)]
pub struct ForcePlatform {
    pub kind: i64,
    pub channels: Vec<i64>,
    pub corners: Vec<[f64; 3]>,
    pub origin: [f64; 3],
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cal_matrix: Vec<f64>,
}

/// The force plates a parameter tree describes.
pub fn force_platforms(p: &Parameters) -> Vec<ForcePlatform> {
    let used = p
        .number("FORCE_PLATFORM", "USED")
        .map_or(0, |u| u.max(0.0) as usize);
    let nums = |name: &str| p.numbers_continued("FORCE_PLATFORM", name);
    let dim0 = |name: &str, default: usize| {
        p.get("FORCE_PLATFORM", name)
            .and_then(|q| q.dims.first().copied())
            .map_or(default, usize::from)
            .max(1)
    };
    let (types, channels, corners, origins, cal) = (
        nums("TYPE"),
        nums("CHANNEL"),
        nums("CORNERS"),
        nums("ORIGIN"),
        nums("CAL_MATRIX"),
    );
    let per_channel = dim0("CHANNEL", 6);
    let cal_len = p.get("FORCE_PLATFORM", "CAL_MATRIX").map_or(0, |q| {
        q.dims.iter().take(2).map(|&d| usize::from(d)).product()
    });
    (0..used.min(64))
        .map(|i| {
            let get = |v: &[f64], k: usize| v.get(k).copied().unwrap_or(f64::NAN);
            ForcePlatform {
                kind: get(&types, i) as i64,
                channels: (0..per_channel)
                    .filter_map(|k| channels.get(i * per_channel + k).map(|&c| c as i64))
                    .collect(),
                corners: (0..4)
                    .map(|c| std::array::from_fn(|a| get(&corners, i * 12 + c * 3 + a)))
                    .collect(),
                origin: std::array::from_fn(|a| get(&origins, i * 3 + a)),
                cal_matrix: cal
                    .get(i * cal_len..(i + 1) * cal_len)
                    .map(<[f64]>::to_vec)
                    .unwrap_or_default(),
            }
        })
        .collect()
}

/// The subjects a file names (`SUBJECTS`): each name, its marker set, and whether its
/// point labels carry the name as a prefix.
#[derive(Debug, Clone, Serialize)]
pub struct Subject {
    pub name: String,
    pub marker_set: String,
    pub uses_prefixes: bool,
}

/// The subjects a parameter tree names.
pub fn subjects(p: &Parameters) -> Vec<Subject> {
    let names = p.strings_continued("SUBJECTS", "NAMES");
    let sets = p.strings_continued("SUBJECTS", "MARKER_SETS");
    let prefixes = p
        .number("SUBJECTS", "USES_PREFIXES")
        .is_some_and(|v| v != 0.0);
    names
        .iter()
        .enumerate()
        .filter(|(_, n)| !n.is_empty())
        .map(|(i, n)| Subject {
            name: n.clone(),
            marker_set: sets.get(i).cloned().unwrap_or_default(),
            uses_prefixes: prefixes,
        })
        .collect()
}

/// What `TRIAL` says of the capture: the trial frames the file holds and the cameras' rate.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Trial {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub actual_start_field: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub actual_end_field: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera_rate: Option<f64>,
}

/// The trial a parameter tree describes.
pub fn trial(p: &Parameters) -> Trial {
    let field = |name: &str| {
        p.u16s("TRIAL", name).and_then(|v| match v.as_slice() {
            [lo, hi, ..] => Some(u64::from(*lo) + (u64::from(*hi) << 16)),
            [lo] => Some(u64::from(*lo)),
            [] => None,
        })
    };
    Trial {
        actual_start_field: field("ACTUAL_START_FIELD"),
        actual_end_field: field("ACTUAL_END_FIELD"),
        camera_rate: p.number("TRIAL", "CAMERA_RATE").filter(|r| r.is_finite()),
    }
}

/// What `GET …/parameters` shows: the tree, and what the well-known groups say read out
/// (force plates, subjects, trial; `POINT`, `ANALOG` and `EVENT` are the take's own
/// points, channels and events).
#[derive(Debug, Clone, Serialize)]
pub struct ParametersView {
    pub force_platforms: Vec<ForcePlatform>,
    pub subjects: Vec<Subject>,
    pub trial: Trial,
    #[serde(flatten)]
    pub parameters: Parameters,
}

/// Take `id`'s parameters as a view; `Unsatisfiable` if its file had none.
pub async fn parameters_view(store: &Store, id: &str) -> Result<ParametersView> {
    let p = parameters(store, id).await?.ok_or_else(|| {
        Error::Unsatisfiable(format!(
            "take {id} has no parameters (only C3D files carry a parameter section)"
        ))
    })?;
    Ok(ParametersView {
        force_platforms: force_platforms(&p),
        subjects: subjects(&p),
        trial: trial(&p),
        parameters: p,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_parse() {
        let b: AnalogBounds = "0.5".parse().unwrap();
        assert_eq!(b.all, Some(0.5));
        let b: AnalogBounds = "*=0.01, Fz1=2".parse().unwrap();
        assert_eq!((b.all, b.by_label["Fz1"]), (Some(0.01), 2.0));
        assert!("Fz1=-1".parse::<AnalogBounds>().is_err());
        assert!("x".parse::<AnalogBounds>().is_err());
    }
}
