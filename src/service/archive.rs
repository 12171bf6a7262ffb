//! For archivists: check everything stored ([`verify`]), get everything out ([`export_take`],
//! files anyone can read plus the exact bitstreams) and back into any store ([`import_take`]),
//! so that no one is locked in and a library can move between SQLite and Postgres.
//!
//! The bitstream of a take is its container (`docs/FORMAT.md`: header with the chunk index,
//! then the chunks) and the bases it names; with the take's row (metadata and statistics) it
//! is everything the store holds of the take, so an import stores the very same bytes.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::answer::{self, Answer, RangeRequest};
use super::budget::{Budget, Holder};
use super::fetch::TimeRange;
use super::prepared::ReadCaches;
use super::take::Take;
use super::{blocking, Error, Result};
use crate::codec::{self, basis::hex, Basis, CodecId, Container, Header, Shared, Skeleton};
use crate::limits::Limits;
use crate::motion::formats::Format;
use crate::motion::transform::Options;
use crate::store::{BasisRow, ChunkEntry, Filter, NewTake, Store};

/// One thing wrong with one stored take.
#[derive(Debug, Clone, Serialize)]
pub struct Problem {
    pub id: String,
    pub name: String,
    pub what: String,
}

/// What [`verify`] found.
#[derive(Debug, Clone, Default, Serialize)]
pub struct VerifyReport {
    pub takes: usize,
    pub chunks: usize,
    pub frames: u64,
    /// Takes stored before decoded digests were kept: decoded and checked, but not compared
    /// bit for bit with what was measured at ingest.
    pub without_digest: usize,
    pub problems: Vec<Problem>,
}

/// Read every chunk of every take matching `filter`, check it against its checksum and the
/// header's index, decode every take and compare what it decodes to with what was measured
/// when it was stored (the decoded digest), and the stored statistics with the take's bound
/// and sizes. `progress` is told each take as it is done.
pub async fn verify(
    store: &Store,
    filter: &Filter,
    mut progress: impl FnMut(&str),
) -> Result<VerifyReport> {
    let mut report = VerifyReport::default();
    for row in super::library::all_rows(store, filter).await? {
        report.takes += 1;
        report.frames += row.totals.frames.max(0) as u64;
        let (id, name) = (row.id.clone(), row.name.clone());
        let mut problem = |what: String| {
            report.problems.push(Problem {
                id: id.clone(),
                name: name.clone(),
                what,
            })
        };
        // A record that does not parse is a problem to report, not a reason to stop.
        let checked = match super::fetch::parse(store, row).await {
            Ok(take) => check_take(store, &take).await,
            Err(e) => Err(e),
        };
        match checked {
            Ok(checked) => {
                report.chunks += checked.chunks;
                for what in checked.problems {
                    problem(what);
                }
                if !checked.had_digest {
                    report.without_digest += 1;
                }
            }
            Err(e) => problem(e.to_string()),
        }
        progress(&name);
    }
    Ok(report)
}

struct Checked {
    chunks: usize,
    had_digest: bool,
    problems: Vec<String>,
}

/// Check one take: its record against its header and chunk index, then its chunks and
/// what they decode to.
async fn check_take(store: &Store, take: &Take) -> Result<Checked> {
    // The chunk rows are read once: a live take's header is made from them.
    let index = store.chunk_index(&take.id).await?;
    let live = take.is_live();
    let header = if live {
        super::fetch::header_from_index(take, &index)?
    } else {
        super::fetch::stored_header(take)?
    };
    let (beside, mut problems) = beside_of(store, take).await?;
    problems.extend(check_record(take, &header, &index, live, beside));
    let had_digest = take.meta.decoded_blake3.is_some();
    problems.extend(check_chunks(store, take, header, index.len()).await?);
    Ok(Checked {
        chunks: index.len(),
        had_digest,
        problems,
    })
}

/// What a take keeps beside its points and counts in its sizes (`add_beside`): raw and
/// stored bytes of its analog channels, parameters and model outputs; and what is wrong
/// with them (model outputs that do not decode, or do not match the take's record).
async fn beside_of(store: &Store, take: &Take) -> Result<((u64, u64), Vec<String>)> {
    let (mut raw, mut stored) = (0u64, 0u64);
    let mut problems = Vec::new();
    if let Some(a) = store.analog(&take.id).await? {
        raw += a.raw_bytes as u64;
        stored += a.stored_bytes as u64;
    }
    if let Some(p) = store.parameters(&take.id).await? {
        stored += p.payload.len() as u64;
    }
    match (store.outputs(&take.id).await?, take.meta.outputs.is_empty()) {
        (None, true) => {}
        (Some(bytes), false) => {
            raw += (take.frames * take.meta.outputs.len() * 12) as u64;
            stored += bytes.len() as u64;
            let (frames, described) = (take.frames, take.meta.outputs.clone());
            let decoded = blocking(move || {
                crate::codec::outputs::decode(&bytes, &codec::DecodeLimits::default())
            })
            .await?;
            match decoded {
                Ok(o) if o.frames() == frames && o.outputs == described => {}
                Ok(_) => problems.push("its model outputs do not match its record".into()),
                Err(e) => problems.push(format!("its model outputs: {e}")),
            }
        }
        (Some(_), true) => problems.push("model outputs its record does not list".into()),
        (None, false) => problems.push("its record lists model outputs that are not stored".into()),
    }
    Ok(((raw, stored), problems))
}

/// What a take's record, header and chunk index must agree on, and its statistics with its
/// bound and sizes (`beside`: the raw and stored bytes kept beside the points).
fn check_record(
    take: &Take,
    header: &Header,
    index: &[ChunkEntry],
    live: bool,
    beside: (u64, u64),
) -> Vec<String> {
    let mut problems = Vec::new();
    if index.len() != header.chunks.len() {
        problems.push(format!(
            "the header indexes {} chunks, {} are stored",
            header.chunks.len(),
            index.len()
        ));
    }
    for (i, (e, m)) in index.iter().zip(&header.chunks).enumerate() {
        if (e.first_frame, e.frames, e.len, e.crc32c)
            != (
                i64::from(m.first_frame),
                i64::from(m.frames),
                i64::from(m.len),
                m.crc32c,
            )
        {
            problems.push(format!(
                "chunk {i}: its take and the header's index disagree"
            ));
        }
    }
    if header.frames as usize != take.frames || header.points as usize != take.points {
        problems.push(format!(
            "the header says {} frames of {} points, the take {} of {}",
            header.frames, header.points, take.frames, take.points
        ));
    }
    if header.codec != take.codec {
        problems.push(format!(
            "the header says codec {}, the take {}",
            header.codec, take.codec
        ));
    }
    // Statistics against the bound and the sizes they were computed from.
    let slack = 1e-9 * take.bound.max_mm().max(1.0);
    if !take.bound.holds(take.max_mm - slack, take.mean_mm - slack) {
        problems.push(format!(
            "stored errors (max {} mm, mean {} mm) are over its bound, {}",
            take.max_mm, take.mean_mm, take.bound
        ));
    }
    if take.raw_bytes != (take.frames * take.points * 12) as u64 + beside.0 {
        problems.push(format!(
            "raw_bytes {} is not frames × points × 12 and what is kept beside the points ({})",
            take.raw_bytes, beside.0
        ));
    }
    let stored = (header.to_bytes().len() + index.iter().map(|e| e.len as usize).sum::<usize>())
        as u64
        + beside.1;
    if !live && stored != take.stored_bytes {
        problems.push(format!(
            "stored_bytes {} but the header, chunks and what is beside them take {stored}",
            take.stored_bytes
        ));
    }
    problems
}

/// Every chunk of a take against its checksum (one by one where the take's read fails, to
/// name the chunk), then the take decoded and compared with the digest it was measured on.
async fn check_chunks(
    store: &Store,
    take: &Take,
    header: Header,
    chunks: usize,
) -> Result<Vec<String>> {
    let mut problems = Vec::new();
    let rows = match store.chunks(&take.id, 0, chunks as i64).await {
        Ok(rows) => rows,
        Err(_) => {
            for i in 0..chunks as i64 {
                if let Err(e) = store.chunks(&take.id, i, i + 1).await {
                    problems.push(format!("chunk {i}: {e}"));
                }
            }
            return Ok(problems);
        }
    };
    let shared = match super::fetch::shared(store, &header).await {
        Ok(b) => b,
        Err(e) => {
            problems.push(format!("its basis or skeleton: {e}"));
            return Ok(problems);
        }
    };
    let decoded = blocking(move || {
        codec::Reader::new(header, shared)?.read_all(&codec::Stored::new(
            0,
            rows.iter().map(|r| r.payload.as_slice()),
        ))
    })
    .await?;
    let digest = take.meta.decoded_blake3.as_deref();
    match decoded {
        Err(e) => problems.push(format!("does not decode: {e}")),
        Ok(frames) => {
            if frames.iter().any(|v| v.is_infinite()) {
                problems.push("decodes to infinite values".into());
            }
            if let Some(want) = digest {
                let got = codec::decoded_digest(&frames);
                if got != want {
                    problems.push(format!(
                        "decodes to other frames than were measured at ingest (digest {got}, \
                         stored {want}): its statistics no longer describe what it serves"
                    ));
                }
            }
        }
    }
    Ok(problems)
}

/// A take as export writes it: its row, its bitstream, the bases that bitstream names, and
/// its frames in a file of an open format, as an answer to be written out piece by piece.
pub struct ExportedTake {
    pub take: Take,
    pub container: Container,
    pub bases: Vec<BasisRow>,
    /// The take's skeleton, if it is a skeleton take.
    pub skeleton: Option<Arc<Skeleton>>,
    pub format: Format,
    /// The open-format file, through the one read path (as `GET …/frames` writes it).
    pub file: Answer,
    /// The analog channels' container, if the take has any.
    pub analog: Option<Container>,
    /// The file's parameters as stored (a zstd C3D parameter section), if it had any.
    pub parameters: Option<Vec<u8>>,
    /// Its model outputs as stored (`codec::outputs` bytes), if it had any.
    pub outputs: Option<Vec<u8>>,
}

/// The open format a take's frames are written back to: its own where we write it, else the
/// closest that keeps names, units and gaps (C3D with its analog channels, events and
/// parameters; BVH → BVH when its codec kept the channel values, else JSON positions).
pub fn export_format(source_format: &str, codec: CodecId) -> Format {
    let keeps_channels = codec::codec(codec).is_ok_and(|c| c.codes_channels());
    match source_format {
        "bvh" if keeps_channels => Format::Bvh,
        "c3d" => Format::C3d,
        "trc" => Format::Trc,
        "npy" => Format::Npy,
        _ => Format::Json,
    }
}

/// What an archive export reads with: the caches, budget and limits of the one read path.
/// The command line reads alone, one take at a time, and must get every stored take out
/// (a C3D stored from a 512 MiB upload included), so its answers are not held to a
/// server's per-answer limits; what it holds is one take's file.
pub struct ReadWith {
    pub caches: Arc<ReadCaches>,
    pub budget: Arc<Budget>,
    pub limits: Limits,
}

impl Default for ReadWith {
    fn default() -> Self {
        let limits = Limits {
            answer_samples: u64::MAX,
            answer_bytes: 1 << 40,
            ..Limits::default()
        };
        ReadWith {
            // Whole takes read past the chunk cache; it only needs to exist.
            caches: Arc::new(ReadCaches::new(0)),
            budget: Arc::new(Budget::new(limits.answer_bytes, limits.answer_bytes)),
            limits,
        }
    }
}

/// Read one take whole: bitstream, bases, and its frames as an open file (an answer of
/// [`answer::open`], the path every output takes).
pub async fn export_take(store: &Store, with: &ReadWith, take: Take) -> Result<ExportedTake> {
    // Its record as reading it leaves it: a take stored before bodies were kept gets its
    // axes now, so that the manifest and the database agree.
    let take = super::body::ensure(store, take).await?;
    let (header, _) = super::fetch::header_of(store, &take).await?;
    let chunks = store
        .chunks(&take.id, 0, header.chunks.len() as i64)
        .await?
        .into_iter()
        .map(|c| c.payload)
        .collect();
    let container = Container { header, chunks };
    let mut bases = Vec::new();
    if let Some(h) = &container.header.basis {
        let id = hex(h);
        let b = store
            .basis(&id)
            .await?
            .ok_or_else(|| Error::NotFound(format!("basis {id}")))?;
        bases.push(b);
    }
    let skeleton = match &take.skeleton {
        Some(id) => Some(super::skeletons::load(store, id).await?),
        None => None,
    };
    let format = export_format(&take.source_format, take.codec);
    // What is kept beside the points: the analog container and the parameters as stored.
    let analog = match super::analog::decoder(store, &take.id).await? {
        Some(d) => {
            let n = d.header().chunks.len() as i64;
            let chunks = store.analog_chunks(&take.id, 0, n).await?;
            Some(Container {
                header: d.header().clone(),
                chunks: chunks.into_iter().map(|c| c.payload).collect(),
            })
        }
        None => None,
    };
    let parameters = store.parameters(&take.id).await?;
    let outputs = store.outputs(&take.id).await?;
    let file = answer::open(
        store,
        &with.caches,
        &with.budget,
        Holder::Token("archive export".into()),
        &with.limits,
        &take.id,
        RangeRequest {
            range: TimeRange::All,
            points: None,
            format,
            transform: Options::default(),
            onto: None,
            feet: Default::default(),
        },
    )
    .await?;
    Ok(ExportedTake {
        take,
        container,
        bases,
        skeleton,
        format,
        file,
        analog,
        parameters: parameters.map(|p| p.payload),
        outputs,
    })
}

/// One line of an export's `manifest.jsonl`: the take's row (its header travels in the
/// bitstream file) and where its files are.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ManifestLine {
    #[serde(flatten)]
    pub take: Take,
    /// The bitstream (container) file, relative to the export folder.
    pub bitstream: String,
    /// The decoded frames in an open format, relative to the export folder.
    pub file: String,
    /// Ids of the bases the bitstream names (files `bases/<id>.mcsb`).
    pub bases: Vec<String>,
    /// The analog channels' bitstream, relative to the export folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub analog: Option<String>,
    /// The file's parameters as stored (zstd of a C3D parameter section).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parameters: Option<String>,
    /// Its model outputs as stored (`codec::outputs`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outputs: Option<String>,
}

/// What an export keeps beside a take's point bitstream: its analog bitstream and its
/// file's parameters, as the files hold them.
#[derive(Debug, Clone, Default)]
pub struct Beside {
    pub analog: Option<Vec<u8>>,
    pub parameters: Option<Vec<u8>>,
    pub outputs: Option<Vec<u8>>,
}

/// What [`import_take`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Imported {
    Stored,
    /// A take with this id is stored already (imports can be repeated).
    AlreadyStored,
}

/// Store an exported take again: its row as exported, its bitstream byte for byte (checked:
/// the container parses, every chunk matches its checksum, and it decodes to the digest it
/// was measured on), the bases it names first (`bases`: each basis's exported row, its
/// payload filled in from its `.mcsb` file).
pub async fn import_take(
    store: &Store,
    line: &ManifestLine,
    bitstream: Vec<u8>,
    bases: Vec<BasisRow>,
    skeleton: Option<Vec<u8>>,
    beside: Beside,
) -> Result<Imported> {
    if store.exists(&line.take.id).await? {
        return Ok(Imported::AlreadyStored);
    }
    let mut loaded = Vec::new();
    for row in bases {
        let b = Basis::parse(&row.payload)
            .map_err(|e| Error::InvalidRequest(format!("basis {}: {e}", row.id)))?;
        if b.id() != row.id || !line.bases.contains(&row.id) {
            return Err(Error::InvalidRequest(format!(
                "basis file {} holds basis {}, which take {} does not name",
                row.id,
                b.id(),
                line.take.id
            )));
        }
        loaded.push((Arc::new(b), row));
    }
    let container = Container::parse(&bitstream, &codec::DecodeLimits::default())
        .map_err(|e| Error::InvalidRequest(format!("bitstream of {}: {e}", line.take.id)))?;
    let header: &Header = &container.header;
    line.take.check()?;
    if header.frames as usize != line.take.frames || header.codec != line.take.codec {
        return Err(Error::InvalidRequest(format!(
            "bitstream of {} does not match its manifest line",
            line.take.id
        )));
    }
    let skeleton = match (&line.take.skeleton, skeleton) {
        (None, None) => None,
        (Some(id), Some(bytes)) => {
            let rig = Skeleton::parse(&bytes, crate::limits::Limits::default().points)
                .map_err(|e| Error::InvalidRequest(format!("skeleton {id}: {e}")))?;
            if rig.id() != *id {
                return Err(Error::InvalidRequest(format!(
                    "skeleton file {id} holds skeleton {}",
                    rig.id()
                )));
            }
            Some(super::skeletons::row_of(
                &rig,
                &line.take.layout,
                line.take.created_at,
            ))
            .map(|row| (Arc::new(rig), row))
        }
        _ => {
            return Err(Error::InvalidRequest(format!(
                "take {} names a skeleton the export does not hold, or the reverse",
                line.take.id
            )))
        }
    };
    let rig = match (&header.rig, &skeleton) {
        (None, _) => None,
        (Some(h), Some((r, _))) if r.hash() == *h => Some(r.clone()),
        (Some(h), _) => {
            return Err(Error::InvalidRequest(format!(
                "the bitstream decodes with skeleton {}, which the take does not name",
                hex(h)
            )))
        }
    };
    let shared = match &header.basis {
        None => None,
        Some(h) => Some(
            loaded
                .iter()
                .find(|(b, _)| b.hash() == *h)
                .map(|(b, _)| b.clone())
                .ok_or_else(|| {
                    Error::InvalidRequest(format!("basis {} is missing from the export", hex(h)))
                })?,
        ),
    };
    let want = line.take.meta.decoded_blake3.clone();
    let (container, shared) = blocking(move || -> Result<(Container, Option<Arc<Basis>>)> {
        let both = Shared {
            basis: shared.clone(),
            rig,
        };
        let frames = codec::decode_all_with(&container, both)?;
        if let Some(want) = want {
            if codec::decoded_digest(&frames) != want {
                return Err(Error::InvalidRequest(
                    "the bitstream decodes to other frames than were measured at ingest".into(),
                ));
            }
        }
        Ok((container, shared))
    })
    .await??;
    if shared.is_some() {
        for (_, row) in &loaded {
            store.insert_basis(row).await?;
        }
    }
    let invalid = |what: &str, e: &dyn std::fmt::Display| {
        Error::InvalidRequest(format!("{what} of {}: {e}", line.take.id))
    };
    let analog = match (beside.analog, &line.take.meta.analog) {
        (None, None) => None,
        (Some(bytes), Some(meta)) => {
            let c = Container::parse(&bytes, &codec::DecodeLimits::default())
                .map_err(|e| invalid("analog bitstream", &e))?;
            if c.header.frames as usize != line.take.frames || c.header.codec != meta.codec {
                return Err(invalid(
                    "analog bitstream",
                    &"does not match its manifest line",
                ));
            }
            let c = blocking(move || codec::analog::decode_all(&c).map(|_| c))
                .await?
                .map_err(|e| invalid("analog bitstream", &e))?;
            Some(super::analog::rows(&c, meta))
        }
        _ => {
            return Err(invalid(
                "analog bitstream",
                &"the manifest line and the export disagree on whether there is one",
            ))
        }
    };
    let parameters = match beside.parameters {
        Some(payload) => {
            let row = crate::store::ParametersRow {
                format: super::analog::PARAMETERS_FORMAT.into(),
                payload,
            };
            super::analog::parameters_of(&line.take.id, &row)
                .map_err(|e| invalid("parameters", &e))?;
            Some(row)
        }
        None => None,
    };
    let outputs = match (beside.outputs, line.take.meta.outputs.is_empty()) {
        (None, true) => None,
        (Some(bytes), false) => {
            let frames = line.take.frames;
            let described = line.take.meta.outputs.clone();
            let checked = bytes.clone();
            blocking(move || {
                let o = codec::outputs::decode(&checked, &codec::DecodeLimits::default())
                    .map_err(|e| e.to_string())?;
                if o.frames() != frames || o.outputs != described {
                    return Err("does not match its manifest line".to_string());
                }
                Ok(())
            })
            .await?
            .map_err(|e| invalid("model outputs", &e))?;
            Some(bytes)
        }
        _ => {
            return Err(invalid(
                "model outputs",
                &"the manifest line and the export disagree on whether there are any",
            ))
        }
    };
    let chunks = super::take::chunk_rows(&container);
    let mut take = line.take.clone();
    take.header = container.header.to_bytes();
    take.live_until = None;
    store
        .insert(&NewTake {
            row: take.to_row()?,
            chunks,
            basis: container.header.basis.as_ref().map(hex),
            skeleton: skeleton.map(|(_, row)| row),
            // An export holds the bitstream, not the original: no series to measure.
            errors: None,
            analog,
            parameters,
            outputs,
            stream: None,
        })
        .await?;
    Ok(Imported::Stored)
}
