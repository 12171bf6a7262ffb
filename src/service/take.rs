//! A stored take as the service knows it: every field typed, its metadata a struct. Parsed
//! from its store row once, at the boundary ([`Take::from_row`]); a row that does not parse
//! is an error naming the take and the field, never a default. Written back with
//! [`Take::to_row`]. The HTTP layer shows takes through its own view; export manifests carry
//! a take's serialised form (below), which reads back with the same checks.

use serde::{Deserialize, Serialize};

use super::choose::Decision;
use super::{Error, Result};
use crate::codec::Skeleton;
use crate::codec::{CodecId, ErrorBound};
use crate::labels::Labels;
use crate::motion::body::{Axes, Body, RoleMap, Roles};
use crate::motion::Unit;
use crate::store::{TakeRow, TakeTotals};

/// One take: what it is, how it was coded, what that cost and what error it measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Take {
    pub id: String,
    pub name: String,
    pub library: String,
    pub tags: Vec<String>,
    /// What the take is of, key → value ([`Labels`]).
    #[serde(default)]
    pub labels: Labels,
    pub fps: f64,
    pub frames: usize,
    pub points: usize,
    pub duration_s: f64,
    pub metres_per_unit: f64,
    /// Layout signature (hex): takes of one layout share bases.
    pub layout: String,
    pub source_format: String,
    pub codec: CodecId,
    /// Stored as `max_bound_mm` and `mean_bound_mm`.
    #[serde(flatten, with = "bound_fields")]
    pub bound: ErrorBound,
    pub raw_bytes: u64,
    pub stored_bytes: u64,
    pub ratio: f64,
    pub mean_mm: f64,
    pub rms_mm: f64,
    pub max_mm: f64,
    pub kg_percent: f64,
    pub meta: TakeMeta,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// The codec container header (its chunk index included once the take is closed).
    #[serde(skip)]
    pub header: Vec<u8>,
    /// While a live stream codes the take: when its lease runs out (ms since the epoch).
    #[serde(skip)]
    pub live_until: Option<i64>,
    /// The stored skeleton of a skeleton take (its id): its hierarchy, and the point names.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skeleton: Option<String>,
    /// Which points play which role: read from the skeleton's joints (or the point names)
    /// whenever a take is parsed, not stored in its row ([`Roles`]).
    #[serde(skip)]
    pub roles: Roles,
    /// How many times its body changed since it was stored (what tells a cached decoder,
    /// which holds the body's stance, that it is stale).
    #[serde(skip)]
    pub body_rev: u64,
}

/// What is kept with a take beside its numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TakeMeta {
    /// One name per point, in stored order. Not stored for a skeleton take: its skeleton
    /// names them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub point_names: Vec<String>,
    /// The unit and where it came from.
    pub unit: Unit,
    /// What reading or coding the take gave up or guessed.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Which codec was chosen and why.
    pub decision: Decision,
    /// [`crate::codec::decoded_digest`] of the frames its statistics were measured on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decoded_blake3: Option<String>,
    /// Why a live take was closed without finishing (its server stopped).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interrupted: Option<String>,
    /// Frames a live stream's producer had sent and been answered for that the take does
    /// not hold: pending on a server that stopped before it committed them.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub frames_lost: usize,
    /// Each time another server took the stream over from one that stopped.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub handovers: Vec<StreamHandover>,
    /// The codec a finished stream was coded with live, before it was re-encoded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reencoded_from: Option<CodecId>,
    /// Events marked in the file (C3D's `EVENT` group): gait events, triggers.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub events: Vec<crate::motion::events::Event>,
    /// The trial frame number of the take's first frame, where its file states one (C3D):
    /// what a C3D written back starts at, so that its events fall where they did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_frame: Option<usize>,
    /// The take's analog channels, how they were coded and what that cost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub analog: Option<AnalogMeta>,
    /// The body's axes in the stored coordinates (up, forward, floor), from anatomy at
    /// ingest, or as given ([`crate::motion::body`]). Absent for live takes and for takes
    /// stored before bodies were kept: the first read derives and stores them
    /// ([`super::body`]). (Such takes may carry `up`, the figure's extent's guess, which
    /// is wrong for long walks: it is not read.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axes: Option<Axes>,
    /// Roles a user set by PATCH (an empty list: played by nothing), applied over the ones
    /// read from the names or shape whenever the take is parsed.
    #[serde(default, skip_serializing_if = "RoleMap::is_empty")]
    pub roles_given: RoleMap,
    /// The model outputs the file carried beside its markers (a C3D's joint angles,
    /// forces, moments, powers): names, kinds, units; their values are read by name
    /// (`/v1/takes/{id}/outputs`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outputs: Vec<crate::motion::outputs::Output>,
}

impl TakeMeta {
    /// As the take's row stores it: JSON text, packed ([`crate::store::packed`]).
    pub fn to_record(&self, id: &str) -> Result<Vec<u8>> {
        let text = serde_json::to_string(self)
            .map_err(|e| Error::Internal(format!("take {id}: meta: {e}")))?;
        crate::store::packed::pack(&text)
            .map_err(|e| Error::Internal(format!("take {id}: meta: {e}")))
    }
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// A live stream taken over by another server after the one coding it stopped: the take
/// goes on at `frame`, and the `frames_lost` frames that server had accepted after it are
/// not in it (their producer may send them again).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StreamHandover {
    pub frame: usize,
    pub frames_lost: usize,
    /// When, ms since the Unix epoch.
    pub at_ms: i64,
}

/// Who a new take is and where it goes: what a client names.
#[derive(Debug, Clone, Default)]
pub struct Label {
    /// Defaults to the take's id.
    pub name: Option<String>,
    pub library: String,
    pub tags: Vec<String>,
    /// What the take is of ([`Labels`], checked).
    pub labels: Labels,
}

impl Take {
    /// A new take of no frames yet, coded with `codec` to `bound` (its shape and unit from
    /// `meta`, its roles from its point names); ingest and streams fill in frames, sizes
    /// and errors as they code it (and a skeleton take's skeleton and roles).
    pub fn new(
        label: &Label,
        source_format: &str,
        fps: f64,
        layout: String,
        codec: CodecId,
        bound: ErrorBound,
        meta: TakeMeta,
    ) -> Take {
        let id = uuid::Uuid::now_v7().to_string();
        let roles = Roles::of_markers(&meta.point_names).with_given(&meta.roles_given);
        Take {
            name: label
                .name
                .clone()
                .filter(|n| !n.trim().is_empty())
                .unwrap_or_else(|| id.clone()),
            id,
            library: label.library.clone(),
            tags: super::normalise_tags(&label.tags),
            labels: label.labels.clone(),
            fps,
            frames: 0,
            points: meta.point_names.len(),
            duration_s: 0.0,
            metres_per_unit: meta.unit.metres_per_unit,
            layout,
            source_format: source_format.to_string(),
            codec,
            bound,
            raw_bytes: 0,
            stored_bytes: 0,
            ratio: 0.0,
            mean_mm: 0.0,
            rms_mm: 0.0,
            max_mm: 0.0,
            kg_percent: 0.0,
            meta,
            created_at: super::now_ms(),
            header: Vec::new(),
            live_until: None,
            skeleton: None,
            roles,
            body_rev: 0,
        }
    }

    /// Parse a stored row; `Corrupt` names the take and what does not parse. `rig` is the
    /// skeleton the row names (`row.skeleton_id`), which names its points.
    pub fn from_row(row: TakeRow, rig: Option<&Skeleton>) -> Result<Take> {
        let id = row.id.clone();
        let corrupt = |what: String| Error::Corrupt(format!("stored take {id}: {what}"));
        let text =
            crate::store::packed::unpack(&row.meta).map_err(|e| corrupt(format!("meta: {e}")))?;
        let mut meta: TakeMeta =
            serde_json::from_str(&text).map_err(|e| corrupt(format!("meta: {e}")))?;
        match (&row.skeleton_id, rig) {
            (None, _) => {}
            (Some(want), Some(r)) if r.id() == *want && meta.point_names.is_empty() => {
                meta.point_names = r.joints().iter().map(|j| j.name.clone()).collect();
            }
            (Some(want), _) => {
                return Err(corrupt(format!(
                    "its skeleton {want} was not supplied, or it also stores point names"
                )))
            }
        }
        let count =
            |what: &str, v: i64| usize::try_from(v).map_err(|_| corrupt(format!("{what} is {v}")));
        let bytes =
            |what: &str, v: i64| u64::try_from(v).map_err(|_| corrupt(format!("{what} is {v}")));
        let mut labels = Labels::new();
        for l in &row.labels {
            let value = crate::labels::Label::from_stored(&l.value, l.number)
                .map_err(|e| corrupt(format!("label {}: {e}", l.key)))?;
            labels
                .insert(&l.key, value)
                .map_err(|e| corrupt(e.to_string()))?;
        }
        let roles = match rig {
            Some(r) => super::skeletons::roles(r),
            None => Roles::of_markers(&meta.point_names),
        }
        .with_given(&meta.roles_given);
        let take = Take {
            frames: count("frames", row.totals.frames)?,
            points: count("points", row.points)?,
            codec: row
                .codec
                .parse()
                .map_err(|e| corrupt(format!("codec: {e}")))?,
            bound: ErrorBound::from_stored(row.max_bound_mm, row.mean_bound_mm)
                .map_err(|e| corrupt(format!("bound: {e}")))?,
            raw_bytes: bytes("raw_bytes", row.totals.raw_bytes)?,
            stored_bytes: bytes("stored_bytes", row.totals.stored_bytes)?,
            id: row.id,
            name: row.name,
            library: row.library,
            tags: row.tags,
            labels,
            fps: row.fps,
            duration_s: row.totals.duration_s,
            metres_per_unit: row.metres_per_unit,
            layout: row.layout,
            source_format: row.source_format,
            ratio: row.totals.ratio,
            mean_mm: row.totals.mean_mm,
            rms_mm: row.totals.rms_mm,
            max_mm: row.totals.max_mm,
            kg_percent: row.totals.kg_percent,
            meta,
            created_at: row.created_at,
            body_rev: bytes("body_rev", row.body_rev)?,
            header: row.header,
            live_until: row.live_until,
            skeleton: row.skeleton_id,
            roles,
        };
        take.check()?;
        Ok(take)
    }

    /// What holds between the fields of any take, stored or imported.
    pub fn check(&self) -> Result<()> {
        let corrupt = |what: String| Error::Corrupt(format!("stored take {}: {what}", self.id));
        if self.meta.point_names.len() != self.points {
            return Err(corrupt(format!(
                "{} point names for {} points",
                self.meta.point_names.len(),
                self.points
            )));
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(corrupt(format!("fps is {}", self.fps)));
        }
        // Labels come deserialised too (an imported manifest line): checked as given ones.
        self.labels.check().map_err(corrupt)?;
        if self.meta.unit.metres_per_unit != self.metres_per_unit {
            return Err(corrupt(format!(
                "meta says {} metres per unit, the row {}",
                self.meta.unit.metres_per_unit, self.metres_per_unit
            )));
        }
        Ok(())
    }

    /// The row to store.
    pub fn to_row(&self) -> Result<TakeRow> {
        let meta = if self.skeleton.is_some() {
            // The skeleton names the points; a row need not repeat them.
            TakeMeta {
                point_names: Vec::new(),
                ..self.meta.clone()
            }
            .to_record(&self.id)?
        } else {
            self.meta.to_record(&self.id)?
        };
        Ok(TakeRow {
            id: self.id.clone(),
            name: self.name.clone(),
            library: self.library.clone(),
            tags: self.tags.clone(),
            labels: label_rows(&self.labels),
            fps: self.fps,
            totals: self.totals(),
            points: self.points as i64,
            metres_per_unit: self.metres_per_unit,
            layout: self.layout.clone(),
            source_format: self.source_format.clone(),
            codec: self.codec.to_string(),
            max_bound_mm: self.bound.max_mm(),
            mean_bound_mm: self.bound.mean_mm(),
            header: self.header.clone(),
            meta,
            created_at: self.created_at,
            body_rev: self.body_rev as i64,
            live_until: self.live_until,
            skeleton_id: self.skeleton.clone(),
        })
    }

    /// What the take costs on disk: its container and its row's metadata and keys
    /// ([`crate::store::disk_bytes`]).
    pub fn disk_bytes(&self) -> Result<u64> {
        let row = self.to_row()?;
        let chunks = crate::codec::Header::parse(&self.header, &Default::default())
            .map_or(0, |(h, _)| h.chunks.len());
        Ok(
            crate::store::disk_bytes(row.totals.stored_bytes, row.text_bytes(), chunks as i64)
                as u64,
        )
    }

    /// The running totals a live take's commits store.
    pub fn totals(&self) -> TakeTotals {
        TakeTotals {
            frames: self.frames as i64,
            duration_s: self.duration_s,
            raw_bytes: self.raw_bytes as i64,
            stored_bytes: self.stored_bytes as i64,
            ratio: self.ratio,
            mean_mm: self.mean_mm,
            rms_mm: self.rms_mm,
            max_mm: self.max_mm,
            kg_percent: self.kg_percent,
        }
    }

    /// The take's body: its stored axes with its roles; `None` until its axes are derived.
    pub fn body(&self) -> Option<Body> {
        self.meta.axes.clone().map(|axes| Body {
            axes,
            roles: self.roles.clone(),
        })
    }

    /// Whether a live stream is still coding the take.
    pub fn is_live(&self) -> bool {
        self.live_until.is_some()
    }

    /// Set the frames coded so far (and the duration they make).
    pub fn set_frames(&mut self, frames: usize) {
        self.frames = frames;
        self.duration_s = frames as f64 / self.fps;
    }

    /// Count what is stored beside the points (analog channels, the file's parameters) in
    /// the take's sizes and ratio: raw counts every sample that was uploaded.
    pub fn add_beside(&mut self, raw_bytes: u64, stored_bytes: u64) {
        self.raw_bytes += raw_bytes;
        self.stored_bytes += stored_bytes;
        self.ratio = self.raw_bytes as f64 / self.stored_bytes.max(1) as f64;
    }

    /// Set what was measured on the stored coding: sizes, the ratio, the errors.
    pub fn set_measured(
        &mut self,
        stored_bytes: usize,
        stats: &crate::motion::metrics::ErrorStats,
    ) {
        self.raw_bytes = (self.frames * self.points * 12) as u64;
        self.stored_bytes = stored_bytes as u64;
        self.ratio = self.raw_bytes as f64 / self.stored_bytes.max(1) as f64;
        self.mean_mm = stats.mean_mm;
        self.rms_mm = stats.rms_mm;
        self.max_mm = stats.max_mm;
        self.kg_percent = if stats.kg_percent.is_finite() {
            stats.kg_percent
        } else {
            0.0
        };
    }
}

/// One analog channel as a take's metadata shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelMeta {
    pub label: String,
    pub unit: String,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    /// The bound it was coded within, in its unit (`None`: exactly).
    pub bound: Option<f64>,
    /// The largest error measured, in its unit.
    pub max_error: f64,
}

/// A take's analog channels: how they were coded and why, and what that cost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnalogMeta {
    pub codec: CodecId,
    pub rate: f64,
    pub samples_per_frame: usize,
    pub channels: Vec<ChannelMeta>,
    /// Bytes the uploaded file held them in (2 per 16-bit value, 4 per float).
    pub raw_bytes: u64,
    pub stored_bytes: u64,
    pub ratio: f64,
    /// Each codec tried and its size.
    pub tried: Vec<(CodecId, u64)>,
    pub reason: String,
    pub encode_ms: f64,
}

/// A take's labels as the rows that store them.
pub fn label_rows(labels: &Labels) -> Vec<crate::store::LabelRow> {
    labels
        .iter()
        .map(|(k, v)| crate::store::LabelRow {
            key: k.clone(),
            value: v.canonical(),
            number: v.is_number(),
        })
        .collect()
}

/// A container's chunks as rows to store.
pub fn chunk_rows(c: &crate::codec::Container) -> Vec<crate::store::ChunkRow> {
    c.header
        .chunks
        .iter()
        .zip(&c.chunks)
        .enumerate()
        .map(|(i, (meta, payload))| chunk_row(i, meta, payload))
        .collect()
}

/// One coded chunk as the row that stores it: the one place a chunk row is made, for
/// whole takes ([`chunk_rows`]) and live streams alike.
pub fn chunk_row(
    index: usize,
    meta: &crate::codec::container::ChunkMeta,
    payload: &[u8],
) -> crate::store::ChunkRow {
    crate::store::ChunkRow {
        idx: index as i64,
        first_frame: i64::from(meta.first_frame),
        frames: i64::from(meta.frames),
        crc32c: meta.crc32c,
        payload: payload.to_vec(),
    }
}

/// An [`ErrorBound`] as the stored columns' fields: `max_bound_mm`, `mean_bound_mm` (absent
/// when no mean was asked for), and, shown but not read back, `max_bound_is_default` (the
/// max is the default cap of the mean). Manifests exported before caps existed carry
/// `bound_kind` and `bound_mm`; a mean bound of theirs had no max, so it reads back with the
/// loosest max a client may state, as migration 0005 stores such takes.
mod bound_fields {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use crate::codec::ErrorBound;
    use crate::limits::MAX_BOUND_MM;

    #[derive(Serialize)]
    struct Shown {
        max_bound_mm: f64,
        #[serde(skip_serializing_if = "Option::is_none")]
        mean_bound_mm: Option<f64>,
        max_bound_is_default: bool,
    }

    #[derive(Deserialize)]
    struct Read {
        max_bound_mm: Option<f64>,
        mean_bound_mm: Option<f64>,
        bound_kind: Option<String>,
        bound_mm: Option<f64>,
    }

    pub fn serialize<S: Serializer>(b: &ErrorBound, s: S) -> Result<S::Ok, S::Error> {
        Shown {
            max_bound_mm: b.max_mm(),
            mean_bound_mm: b.mean_mm(),
            max_bound_is_default: b.max_is_default(),
        }
        .serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<ErrorBound, D::Error> {
        use serde::de::Error;
        let f = Read::deserialize(d)?;
        let (max, mean) = match (f.max_bound_mm, f.bound_kind.as_deref(), f.bound_mm) {
            (Some(max), _, _) => (max, f.mean_bound_mm),
            (None, Some("max"), Some(v)) => (v, None),
            (None, Some("mean"), Some(v)) => (MAX_BOUND_MM.max(v), Some(v)),
            _ => return Err(D::Error::custom("a take needs max_bound_mm")),
        };
        ErrorBound::from_stored(max, mean).map_err(D::Error::custom)
    }
}

impl Take {
    /// A small take's record, for tests.
    #[cfg(test)]
    pub(crate) fn sample() -> Take {
        use crate::motion::UnitSource;

        Take {
            id: "t".into(),
            name: "walk".into(),
            library: "lib".into(),
            tags: vec!["a".into()],
            labels: Labels::parse("content:walk,n:3").unwrap(),
            fps: 120.0,
            frames: 10,
            points: 2,
            duration_s: 10.0 / 120.0,
            metres_per_unit: 0.001,
            layout: "ab".into(),
            source_format: "trc".into(),
            codec: CodecId::Quant,
            bound: ErrorBound::mean(0.5),
            raw_bytes: 240,
            stored_bytes: 100,
            ratio: 2.4,
            mean_mm: 0.2,
            rms_mm: 0.25,
            max_mm: 0.4,
            kg_percent: 0.01,
            meta: TakeMeta {
                point_names: vec!["a".into(), "b".into()],
                unit: Unit::new(0.001, UnitSource::Declared).unwrap(),
                warnings: vec![],
                decision: Decision {
                    winner: CodecId::Quant,
                    reason: "asked".into(),
                    tried: vec![],
                    skipped: vec![],
                    keep: None,
                    pruned: vec![],
                },
                decoded_blake3: Some("00".into()),
                interrupted: None,
                frames_lost: 0,
                handovers: Vec::new(),
                reencoded_from: None,
                first_frame: None,
                events: Vec::new(),
                analog: None,
                axes: Some(Axes {
                    up: Some(crate::motion::body::Axis::Z),
                    forward: None,
                    floor_m: Some(0.0),
                    up_from: Some(crate::motion::body::Source::Format),
                    forward_from: None,
                    reason: "a lab C3D is Z-up by convention".into(),
                }),
                roles_given: RoleMap::new(),
                outputs: Vec::new(),
            },
            created_at: 1,
            header: vec![1, 2, 3],
            live_until: None,
            skeleton: None,
            roles: Roles::of_markers(&["a".into(), "b".into()]),
            body_rev: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn take() -> Take {
        Take::sample()
    }

    #[test]
    fn a_take_round_trips_through_its_row() {
        let t = take();
        assert_eq!(Take::from_row(t.to_row().unwrap(), None).unwrap(), t);
    }

    #[test]
    fn a_corrupt_meta_is_an_error_not_an_empty_record() {
        for (meta, says) in [
            ("{not json", "meta"),
            ("{}", "meta: missing field `unit`"),
            (
                r#"{"point_names": ["a"], "unit": {"metres_per_unit": 0.001, "source": {"kind": "declared"}}, "decision": {"winner": "quant", "reason": "", "tried": [], "skipped": []}}"#,
                "1 point names for 2 points",
            ),
            (r#"{"point_names": "a,b"}"#, "meta: invalid type"),
        ] {
            let mut row = take().to_row().unwrap();
            row.meta = crate::store::packed::pack(meta).unwrap();
            let e = Take::from_row(row, None).unwrap_err();
            assert!(matches!(e, Error::Corrupt(_)), "{meta}: {e}");
            assert!(
                e.to_string().contains("stored take t") && e.to_string().contains(says),
                "{meta}: {e}"
            );
        }
        // Bytes that are not a packed record at all (JSON text, as rows held before
        // migration 0018 packed them).
        let mut row = take().to_row().unwrap();
        row.meta = take().meta.to_record("t").unwrap()[1..].to_vec();
        let e = Take::from_row(row, None).unwrap_err();
        assert!(e.to_string().contains("meta: "), "{e}");
        let mut row = take().to_row().unwrap();
        row.meta = serde_json::to_vec(&take().meta).unwrap();
        let e = Take::from_row(row, None).unwrap_err();
        assert!(e.to_string().contains("format byte 123"), "{e}");
        let mut row = take().to_row().unwrap();
        row.max_bound_mm = f64::NAN;
        assert!(matches!(Take::from_row(row, None), Err(Error::Corrupt(_))));
        let mut row = take().to_row().unwrap();
        row.mean_bound_mm = Some(-1.0);
        assert!(matches!(Take::from_row(row, None), Err(Error::Corrupt(_))));
        let mut row = take().to_row().unwrap();
        row.codec = "zip".into();
        assert!(matches!(Take::from_row(row, None), Err(Error::Corrupt(_))));
        let mut row = take().to_row().unwrap();
        row.totals.frames = -1;
        assert!(matches!(Take::from_row(row, None), Err(Error::Corrupt(_))));
    }

    #[test]
    fn the_serialised_take_names_its_bound_as_stored() {
        let v = serde_json::to_value(take()).unwrap();
        assert_eq!(
            (
                v["max_bound_mm"].as_f64(),
                v["mean_bound_mm"].as_f64(),
                v["max_bound_is_default"].as_bool()
            ),
            (Some(5.0), Some(0.5), Some(true))
        );
        assert_eq!(v["codec"], "quant");
        assert!(v.get("header").is_none() && v.get("bound").is_none());
        let back: Take = serde_json::from_value(v.clone()).unwrap();
        assert_eq!(back.bound, ErrorBound::mean(0.5));
        // A manifest from before caps: a max bound reads as it was; a mean bound had no
        // max, and reads back with the loosest.
        let mut old = v.as_object().unwrap().clone();
        for f in ["max_bound_mm", "mean_bound_mm", "max_bound_is_default"] {
            old.remove(f);
        }
        for (kind, want) in [
            ("max", ErrorBound::max(0.5)),
            ("mean", ErrorBound::both(crate::limits::MAX_BOUND_MM, 0.5)),
        ] {
            old.insert("bound_kind".into(), kind.into());
            old.insert("bound_mm".into(), 0.5.into());
            let back: Take = serde_json::from_value(old.clone().into()).unwrap();
            assert_eq!(back.bound, want);
        }
        old.remove("bound_kind");
        assert!(serde_json::from_value::<Take>(old.into()).is_err());
    }
}
