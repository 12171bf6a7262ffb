//! Range answers, written piece by piece: a take's frames in any output format, decoded a
//! chunk at a time and written as they are decoded, so that what a request holds does not
//! grow with the take's length.
//!
//! # What an answer may hold
//! Before anything is decoded, [`open`] checks the request (the range, each point named once,
//! the answer's size against [`Limits::answer_samples`]) and reserves from the server's
//! answer budget ([`Limits::answer_bytes`], a share per caller) what the answer will hold at
//! most, computed from the take's chunk index:
//! - the chunk being decoded, twice (the decoded frames and the decoder's working copy);
//! - the stored payloads read ahead from the store, at most [`PAYLOAD_BATCH`] (or one chunk,
//!   if a chunk is larger);
//! - [`PIECES_IN_FLIGHT`] pieces of output of at most [`PIECE_BYTES`] (or one frame's text,
//!   if a frame is larger), handed to the connection but not yet written.
//!
//! A request over what is free is refused at once (503, `Retry-After`); once open, an answer
//! keeps within its reservation, and each buffer it holds is counted
//! ([`super::budget::Reservation::hold`]) so that `/metrics` reports what answers really
//! hold and the tests check it against what they reserved.
//!
//! Short ranges (at most [`CACHED_CHUNKS`] chunks: what the viewer asks for) go through the
//! server's cache of decoded chunks; longer ones read past it, so a bulk read does not evict
//! what range requests keep hot.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use bytes::Bytes;

use super::budget::{Budget, Held, Holder, Reservation};
use super::fetch::TimeRange;
use super::prepared::prepare;
use super::prepared::{Prepared, ReadCaches};
use super::shape::Shaper;
use super::{blocking, Error, Result};
use crate::codec::read::Chunk;
use crate::codec::{self, basis::hex, ChunkSource};
use crate::limits::Limits;
use crate::motion::formats::bvh::ChannelWriter;
use crate::motion::formats::{frame_writer, Format, FrameWriter, Shape};
use crate::motion::transform::{Axis, Options};
use crate::motion::{Unit, UnitSource};
use crate::store::{ChunkRow, Store};

/// Stored payloads an answer reads ahead in one query, bytes (at least one chunk).
pub const PAYLOAD_BATCH: u64 = 1 << 20;

/// Output is handed on in pieces of about this many bytes (at least one frame).
pub const PIECE_BYTES: usize = 256 << 10;

/// Pieces an answer counts as its own after handing them on: the connection's write queue
/// holds a few before they reach the socket.
pub const PIECES_IN_FLIGHT: u64 = 4;

/// Room a piece keeps for a format's tail (`]}` and a newline for JSON).
const TAIL_BYTES: usize = 64;

/// Ranges of at most this many chunks are decoded through the server's chunk cache.
pub const CACHED_CHUNKS: usize = 8;

/// The most bytes of a cached chunk's frames an answer copies on the request's own task
/// instead of the blocking pool: a few tens of microseconds of copying, less than the hop
/// to the pool and back (what profiling a one-second range read showed, docs/PROFILING.md).
const INLINE_COPY_BYTES: usize = 1 << 20;

/// The names of the points a written file holds, in order: the take's `points`, then those
/// the transforms add after them (`root=extract`'s path and heading) up to the answer's
/// `count`; none when the file holds joints, not points (BVH: `count` is `None`).
pub fn points_written(mut points: Vec<String>, count: Option<usize>) -> Vec<String> {
    let Some(count) = count else {
        return Vec::new();
    };
    let extra = [
        crate::motion::transform::ROOT_MOTION,
        crate::motion::transform::ROOT_MOTION_FORWARD,
    ];
    let added = count.saturating_sub(points.len()).min(extra.len());
    points.truncate(count);
    points.extend(extra[..added].iter().map(|n| n.to_string()));
    points
}

/// How long a reader of many takes (a library export, motion statistics) waits for room in
/// the answer budget before its next take: other answers end within seconds, and an export
/// half sent cannot answer 503 any more.
pub const BUDGET_WAIT: std::time::Duration = std::time::Duration::from_secs(30);

/// An answer written piece by piece ([`Answer`], a library export's ZIP): what the HTTP
/// layer streams, the first piece before the status.
pub trait Pieces: Send + 'static {
    /// The next piece; `None` once the answer is whole.
    fn next_piece(&mut self) -> impl std::future::Future<Output = Result<Option<Bytes>>> + Send;
    /// What the answer is, for the log when it fails part way.
    fn what(&self) -> String;
    /// Whether every piece has been taken: an answer whole after its first piece is sent
    /// as one body, not as a stream of one.
    fn finished(&self) -> bool {
        false
    }
}

impl Pieces for Answer {
    fn next_piece(&mut self) -> impl std::future::Future<Output = Result<Option<Bytes>>> + Send {
        self.next()
    }

    fn what(&self) -> String {
        format!("range answer of take {}", self.id)
    }

    fn finished(&self) -> bool {
        self.tail_done && self.pending.is_empty()
    }
}

/// A range request, parsed: which frames, which points, which format, which transforms.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeRequest {
    pub range: TimeRange,
    /// Point names, each once; `None` for every point.
    pub points: Option<Vec<String>>,
    pub format: Format,
    /// Frame rate, root motion, up axis and unit of the answer ([`super::shape`]).
    pub transform: Options,
    /// The skeleton the take's motion is put on (`skeleton=`); `None` keeps its own.
    pub onto: Option<Arc<super::retarget::Target>>,
    /// What is done to its feet there (`feet=`).
    pub feet: super::retarget::Feet,
}

/// One answer, open: what it holds (for the response's headers) and its pieces, taken with
/// [`Answer::next`].
pub struct Answer {
    pub id: String,
    pub format: Format,
    pub start: usize,
    pub end: usize,
    /// The answer's frames (the range's, or as many as resampling gives) and their rate.
    pub frames_out: usize,
    pub fps: f64,
    /// The take's own rate.
    pub source_fps: f64,
    pub metres_per_unit: f64,
    /// Points per frame (none for BVH, which answers joint channels).
    pub points: Option<usize>,
    /// The answer's length in bytes, where the format fixes it (f32, NPY).
    pub length: Option<u64>,
    /// The most bytes the answer can be (a library export's ZIP marks entries that may pass
    /// 4 GiB as ZIP64).
    pub len_bound: u64,
    store: Store,
    caches: Arc<ReadCaches>,
    prepared: Arc<Prepared>,
    reservation: Arc<Reservation>,
    writer: Writer,
    /// The transforms between decoder and writer; `None` when none is asked for.
    shaper: Option<Shaper>,
    /// The next chunk to decode, and the end of those the range lies in.
    next_chunk: usize,
    last_chunk: usize,
    cache: bool,
    /// Stored payloads read ahead, from `next_chunk` on.
    batch: VecDeque<(ChunkRow, Held)>,
    /// The decoded frames not yet written.
    block: Option<Block>,
    /// Output written but not yet handed on: the head first. Allocated at a piece's full
    /// size ([`Answer::fresh_piece`]), so that what a piece holds is what was reserved for
    /// it, not twice that by doubling.
    pending: Vec<u8>,
    /// The most bytes a frame takes, and the frames not yet written.
    frame_bytes: usize,
    frames_left: usize,
    tail_done: bool,
}

/// How an answer turns decoded frames into bytes.
enum Writer {
    /// Positions (JSON, CSV, TRC, NPY, f32), of every point or the selected ones.
    Points {
        writer: Box<dyn FrameWriter>,
        selected: Option<Vec<usize>>,
    },
    /// BVH: the skeleton's channel values, for codecs that keep them.
    Channels {
        writer: ChannelWriter,
        channels: usize,
    },
    /// glTF: the whole answer is gathered (a glTF's accessors run channel by channel, not
    /// frame by frame), then written at the end.
    Whole(Box<Whole>),
}

/// A glTF answer being gathered: shaped frames of positions or channels.
struct Whole {
    format: Format,
    /// `Some` for a skeleton's channels, `None` for points.
    joints: Option<Vec<crate::motion::skeleton::Joint>>,
    names: Vec<String>,
    values: Vec<f64>,
    frames: usize,
    extras: serde_json::Value,
    name: String,
    fps: f64,
    /// For C3D: the take's analog channels, parameters and trial frames.
    c3d: Option<C3dParts>,
    /// The metres a unit of the values is and the up axis they were turned to (FBX states
    /// both in its settings).
    space: (f64, Axis),
    /// The character file the target skeleton skins: a glTF answer is it playing the take,
    /// read back under the service's limits (as it was read when uploaded).
    character: Option<Arc<Vec<u8>>>,
    read_limits: crate::motion::formats::ReadLimits,
    _held: Option<Held>,
}

/// What a C3D answer writes beside the points.
struct C3dParts {
    /// The analog decoder, and the analog rows a written frame holds (the take's, or as
    /// many as fall in a resampled frame).
    analog: Option<(codec::analog::Decoder, usize)>,
    first_frame: usize,
    metres_per_unit: f64,
}

/// What a glTF or FBX is written from, owned (it is written on the blocking pool).
struct GltfFile {
    format: Format,
    space: (f64, Axis),
    character: Option<Arc<Vec<u8>>>,
    read_limits: crate::motion::formats::ReadLimits,
    joints: Option<Vec<crate::motion::skeleton::Joint>>,
    names: Vec<String>,
    values: Vec<f64>,
    frames: usize,
    fps: f64,
    name: String,
    extras: serde_json::Value,
}

impl Whole {
    /// The gathered frames, taken, with what the file needs.
    fn file(&mut self) -> GltfFile {
        GltfFile {
            format: self.format,
            space: self.space,
            character: self.character.clone(),
            read_limits: self.read_limits,
            joints: self.joints.clone(),
            names: self.names.clone(),
            values: std::mem::take(&mut self.values),
            frames: self.frames,
            fps: self.fps,
            name: self.name.clone(),
            extras: self.extras.clone(),
        }
    }
}

impl GltfFile {
    fn write(self) -> Result<Vec<u8>> {
        use crate::motion::formats::gltf::{self, character, Figure, Scene};
        if let (Some(file), Some(joints), Format::Glb | Format::Gltf) =
            (&self.character, &self.joints, self.format)
        {
            let motion = character::Motion {
                name: &self.name,
                joints,
                values: &self.values,
                frames: self.frames,
                fps: self.fps,
                extras: self.extras.clone(),
            };
            return character::animate(
                file,
                &self.read_limits,
                &motion,
                self.format == Format::Glb,
            )
            .map_err(|e| Error::Corrupt(format!("the stored character file: {e}")));
        }
        let figure = match &self.joints {
            Some(joints) => Figure::Skeleton {
                joints,
                values: &self.values,
            },
            None => Figure::Markers {
                names: &self.names,
                positions: &self.values,
            },
        };
        let scene = Scene {
            name: &self.name,
            figure,
            frames: self.frames,
            fps: self.fps,
            extras: self.extras.clone(),
        };
        Ok(match self.format {
            Format::Gltf => gltf::gltf(&scene),
            Format::Fbx => {
                return crate::motion::formats::fbx::write::fbx(&scene, self.space.0, self.space.1)
                    .map_err(|e| Error::InvalidRequest(e.to_string()))
            }
            _ => gltf::glb(&scene),
        })
    }
}

/// Decoded frames of one chunk (the part in the range), and how many are written.
struct Block {
    data: Decoded,
    frames: usize,
    written: usize,
    _held: Held,
}

enum Decoded {
    Positions(Vec<f32>),
    /// Every point of a chunk's frames as the decoded-chunk cache holds them, from row
    /// `first` on: written straight from the cache (the cache counts their memory).
    Cached {
        chunk: Arc<Vec<f32>>,
        first: usize,
    },
    Channels(codec::skeleton::Channels),
}

/// The transforms of a request as `format` takes them, checked: glTF is metres and +Y up
/// whatever the take's (those are filled in); C3D keeps the lab's axes, units and root
/// motion. The same for every take, so a library export checks it once.
pub fn transform_for(format: Format, mut transform: Options) -> Result<Options> {
    super::shape::check(&transform)?;
    match format {
        Format::Glb | Format::Gltf => {
            if transform.metres_per_unit.is_some_and(|m| m != 1.0) {
                return Err(Error::InvalidRequest(
                    "glTF is in metres: leave out unit".into(),
                ));
            }
            if transform.up.is_some_and(|u| u != Axis::Y) {
                return Err(Error::InvalidRequest("glTF is +Y up: leave out up".into()));
            }
            transform.metres_per_unit = Some(1.0);
            transform.up = Some(Axis::Y);
        }
        Format::Fbx => {
            // FBX states its axes: the body's up turned to +Y (Maya's, and what every
            // importer expects) unless +Z is asked for; the take's unit unless one is.
            if transform.up.is_some_and(|u| u != Axis::Y && u != Axis::Z) {
                return Err(Error::InvalidRequest(
                    "FBX is written +Y or +Z up: up=y or up=z".into(),
                ));
            }
            transform.up = Some(transform.up.unwrap_or(Axis::Y));
        }
        Format::C3d
            if transform.root != crate::motion::transform::Root::Keep
                || transform.up.is_some()
                || transform.metres_per_unit.is_some() =>
        {
            return Err(Error::InvalidRequest(
                "C3D keeps the lab's axes, units and root motion (its parameters place the \
                 force plates in them): leave out root, up and unit (fps applies)"
                    .into(),
            ));
        }
        _ => {}
    }
    Ok(transform)
}

/// Check a range request and open its answer, reserving what it will hold from `budget`
/// for `holder`. Nothing is decoded yet; what cannot be answered is refused here.
pub async fn open(
    store: &Store,
    caches: &Arc<ReadCaches>,
    budget: &Arc<Budget>,
    holder: Holder,
    limits: &Limits,
    id: &str,
    req: RangeRequest,
) -> Result<Answer> {
    let reservation = budget.reservation(holder);
    open_with(store, caches, reservation, limits, id, req).await
}

/// [`open_with`] into a fresh reservation from `reserve`, waiting up to `wait` while the
/// answer budget is full: for a part of a larger answer already under way (a library
/// export's next take, a batch's next range), which can no longer answer 503. Other
/// answers end within seconds.
pub async fn open_waiting(
    store: &Store,
    caches: &Arc<ReadCaches>,
    reserve: impl Fn() -> Reservation,
    limits: &Limits,
    id: &str,
    req: RangeRequest,
    wait: std::time::Duration,
) -> Result<Answer> {
    let waited = std::time::Instant::now();
    loop {
        match open_with(store, caches, reserve(), limits, id, req.clone()).await {
            Err(Error::Busy(_)) if waited.elapsed() < wait => {
                tokio::time::sleep(std::time::Duration::from_millis(200)).await;
            }
            other => return other,
        }
    }
}

/// [`open`], reserving into `reservation` (empty; a library export's takes reserve beside
/// the export's own, [`Budget::reservation_beside`]).
pub async fn open_with(
    store: &Store,
    caches: &Arc<ReadCaches>,
    mut reservation: Reservation,
    limits: &Limits,
    id: &str,
    req: RangeRequest,
) -> Result<Answer> {
    let Planned {
        prepared,
        start,
        end,
        chunks,
        frames_out,
        fps,
        metres_per_unit,
        mut writer,
        points,
        shaper,
        block_bytes,
        frame_bytes,
        head,
        length,
        len_bound,
        bound,
    } = plan(store, caches, limits, id, &req).await?;
    reservation
        .grow_to(bound)
        .map_err(|r| Error::Busy(format!("{}; retry shortly", r.reason("range answers"))))?;
    let reservation = Arc::new(reservation);
    if let Writer::Whole(w) = &mut writer {
        // What gathering holds, counted from the start: it is the answer's bulk.
        w._held = Some(reservation.hold(block_bytes));
    }
    Ok(Answer {
        id: id.to_string(),
        format: req.format,
        start,
        end,
        frames_out,
        fps,
        source_fps: prepared.fps,
        metres_per_unit,
        points,
        length,
        len_bound,
        store: store.clone(),
        caches: caches.clone(),
        cache: chunks.len() <= CACHED_CHUNKS,
        next_chunk: chunks.start,
        last_chunk: chunks.end,
        prepared,
        reservation,
        writer,
        shaper,
        batch: VecDeque::new(),
        block: None,
        pending: {
            let room = (frames_out * frame_bytes as usize).min(PIECE_BYTES);
            let mut first =
                Vec::with_capacity(head.len().max(room) + frame_bytes as usize + TAIL_BYTES);
            first.extend_from_slice(&head);
            first
        },
        frame_bytes: frame_bytes as usize,
        frames_left: frames_out,
        tail_done: false,
    })
}

/// Check a range request exactly as [`open_with`] does, reserving and decoding nothing:
/// what a batch of ranges checks of every part before it writes the first
/// ([`super::ranges`]). The answer's samples (frames × points; joints and End Sites for
/// BVH).
pub async fn check(
    store: &Store,
    caches: &Arc<ReadCaches>,
    limits: &Limits,
    id: &str,
    req: &RangeRequest,
) -> Result<u64> {
    let p = plan(store, caches, limits, id, req).await?;
    let points = p.points.unwrap_or(p.prepared.point_names.len());
    Ok(p.frames_out as u64 * points as u64)
}

/// A range request checked and planned: what [`open_with`] needs to build the answer, and
/// the most it will hold (`bound`, to reserve).
struct Planned {
    prepared: Arc<Prepared>,
    start: usize,
    end: usize,
    chunks: std::ops::Range<usize>,
    frames_out: usize,
    fps: f64,
    metres_per_unit: f64,
    writer: Writer,
    points: Option<usize>,
    shaper: Option<Shaper>,
    block_bytes: u64,
    frame_bytes: u64,
    head: Vec<u8>,
    length: Option<u64>,
    len_bound: u64,
    bound: u64,
}

/// Everything [`open_with`] refuses, checked, and its plan; nothing reserved or decoded.
async fn plan(
    store: &Store,
    caches: &Arc<ReadCaches>,
    limits: &Limits,
    id: &str,
    req: &RangeRequest,
) -> Result<Planned> {
    let req = req.clone();
    // What the request asks is checked before the take is: a rate past the limit is a 400
    // whatever the range (which is the take's to refuse, with a 416).
    let transform = transform_for(req.format, req.transform)?;
    let (prepared, (start, asked_end)) = prepare(store, caches, id, req.range).await?;
    let onto = req.onto.as_deref();
    if onto.is_some() {
        super::retarget::check_format(req.format)?;
    } else if req.feet != super::retarget::Feet::Free {
        return Err(Error::InvalidRequest(
            "feet=lock holds the feet of a take put on another skeleton: give skeleton= too".into(),
        ));
    }
    // Resampled, the range's last output frames may lie past its last source frame: they
    // are interpolated from the frames after it (C3D keeps its range: its analog and
    // outputs go frame for frame with the points).
    let (end, frames_out) = super::shape::span(
        &prepared,
        &transform,
        req.format != Format::C3d,
        (start, asked_end),
        req.range.seconds_from(start, asked_end, prepared.fps),
    );
    // Points a skeleton answer writes: the take's joints, or the target's.
    let joints_out = onto.map_or(prepared.point_names.len(), |t| t.joints.len());
    let header = prepared.reader.header();
    let chunks = prepared.reader.chunks_for(start..end)?;
    let metas = &header.chunks[chunks.clone()];
    // The largest chunk the range lies in, decoded, and the most of it the answer keeps.
    let chunk_frames = metas.iter().map(|c| c.frames as u64).max().unwrap_or(0);
    let part_frames = metas
        .iter()
        .map(|c| {
            let r = c.frame_range();
            (r.end.min(end) - r.start.max(start)) as u64
        })
        .max()
        .unwrap_or(0);
    let max_payload = metas.iter().map(|c| u64::from(c.len)).max().unwrap_or(0);
    let all_payloads: u64 = metas.iter().map(|c| u64::from(c.len)).sum();
    let frames = end - start;
    // Resampling up makes a block of output frames from a block of decoded ones.
    let grow = |n: u64| (n as f64 * frames_out as f64 / frames.max(1) as f64).ceil() as u64 + 2;
    let span = Span {
        id,
        start,
        end: asked_end,
        frames: frames_out,
        chunk_frames,
        part_frames,
    };
    let Plan {
        mut writer,
        points,
        decode_bytes,
        block_bytes,
        frame_bytes,
        shaper,
    } = match req.format {
        Format::Bvh => {
            if req.points.is_some() {
                return Err(Error::InvalidRequest(
                    "BVH output is the whole skeleton: leave out points".into(),
                ));
            }
            // As many samples as the skeleton's joints and End Sites would be as points.
            check_size(frames_out, joints_out, limits)?;
            let rig = channels_rig(store, &prepared).await?;
            let shaper = (!transform.is_identity() || onto.is_some())
                .then(|| {
                    Shaper::channels(&prepared, rig.joints(), &transform, frames, onto, req.feet)
                })
                .transpose()?
                .map(|s| s.limited(frames_out));
            Plan::channels(
                &rig,
                &prepared,
                shaper,
                frames_out,
                chunk_frames,
                grow(part_frames),
            )
        }
        Format::C3d => {
            if req.points.is_some() {
                return Err(Error::InvalidRequest(
                    "C3D output is the whole take (points, analog, parameters): leave out \
                     points"
                        .into(),
                ));
            }
            check_size(frames_out, joints_out, limits)?;
            let take = super::fetch::take(store, id).await?;
            if take.is_live() {
                return Err(Error::Unsatisfiable(format!(
                    "take {id} is being streamed; C3D is written once it is finished"
                )));
            }
            let shaper = Shaper::points(&prepared, &transform, frames, None)?.limited(frames_out);
            let decoder = super::analog::decoder(store, id).await?;
            let analog = match decoder {
                None => None,
                Some(d) => {
                    let per_frame = crate::motion::analog::per_frame_at(
                        d.layout().per_frame,
                        prepared.fps,
                        transform.fps.unwrap_or(prepared.fps),
                    )
                    .map_err(Error::InvalidRequest)?;
                    Some((d, per_frame))
                }
            };
            let words = analog
                .as_ref()
                .map_or(0, |(d, k)| d.layout().channels.len() * k);
            // The markers and the model outputs written back among them.
            let points_out = shaper.width() / 3 + take.meta.outputs.len();
            let file = crate::motion::formats::c3d::write::data_len(frames_out, points_out, words)
                + 256 * 512;
            if file > limits.answer_bytes {
                return Err(Error::InvalidRequest(format!(
                    "a C3D of {frames_out} frames is about {file} bytes, over the limit of {} \
                     for one answer; ask for a shorter range",
                    limits.answer_bytes
                )));
            }
            // Gathered positions (f64, then their f32 copy), the decoded analog (whole
            // chunks; `words` a frame at the answer's rate) and the file.
            let gathered = frames_out as u64 * points_out as u64 * (24 + 12);
            let analog_bytes = frames_out as u64 * words as u64 * 8 * 2;
            let first = take.meta.first_frame.unwrap_or(1) + start;
            let c3d = C3dParts {
                analog,
                // The trial frame of the first frame written, at the answer's rate.
                first_frame: match transform.fps {
                    Some(fps) => {
                        crate::motion::transform::resample::trial_frame_at(first, prepared.fps, fps)
                    }
                    None => first,
                },
                metres_per_unit: transform
                    .metres_per_unit
                    .unwrap_or(prepared.metres_per_unit),
            };
            Plan::whole(
                &prepared,
                req.format,
                shaper,
                frames_out,
                &span,
                file + gathered + analog_bytes,
                Some(c3d),
            )
        }
        Format::Glb | Format::Gltf | Format::Fbx => {
            if req.points.is_some() {
                return Err(Error::InvalidRequest(format!(
                    "{} output is the whole take: leave out points",
                    if req.format == Format::Fbx {
                        "FBX"
                    } else {
                        "glTF"
                    }
                )));
            }
            check_size(frames_out, joints_out, limits)?;
            let keeps =
                codec::codec(prepared.reader.header().codec).is_ok_and(|c| c.codes_channels());
            let shaper = if keeps || onto.is_some() {
                let rig = channels_rig(store, &prepared).await?;
                Shaper::channels(&prepared, rig.joints(), &transform, frames, onto, req.feet)?
                    .limited(frames_out)
            } else {
                Shaper::points(&prepared, &transform, frames, None)?.limited(frames_out)
            };
            let nodes = shaper
                .joints()
                .map_or(shaper.width() / 3, <[crate::motion::skeleton::Joint]>::len);
            // The character file the target skins comes along in a glTF.
            let character = match onto.and_then(|t| t.character.as_deref()) {
                Some(rig) if req.format != Format::Fbx => {
                    if transform.root == crate::motion::transform::Root::Extract {
                        return Err(Error::InvalidRequest(
                            "root=extract adds a root_motion joint above the character's, \
                             which its file does not have: ask for root=in-place, or for BVH \
                             or FBX"
                                .into(),
                        ));
                    }
                    Some(super::skeletons::character(store, rig).await?)
                }
                _ => None,
            };
            let file = match &character {
                _ if req.format == Format::Fbx => {
                    crate::motion::formats::fbx::write::len_bound(frames_out, nodes)
                }
                Some(c) => {
                    crate::motion::formats::gltf::character::len_bound(c.len(), frames_out, nodes)
                }
                None => crate::motion::formats::gltf::glb_len_bound(frames_out, nodes),
            };
            let gathered = frames_out as u64 * shaper.width() as u64 * 8;
            // Building it holds the binary buffer and the file: a GLB is the buffer once
            // more; a glTF is its base64 (4/3 of it) inside the JSON text.
            // A character's file is copied in as well (its buffer, beside the one kept, and
            // its document), and the answer is the whole file again.
            let build = file.saturating_mul(match (req.format, &character) {
                (Format::Gltf, _) | (_, Some(_)) => 4,
                _ => 2,
            });
            if build.saturating_add(gathered) > limits.answer_bytes {
                return Err(Error::InvalidRequest(format!(
                    "a {} of {frames_out} frames of {nodes} nodes takes about {} bytes to \
                     build, over the limit of {} for one answer; ask for a shorter range or a \
                     lower fps",
                    if req.format == Format::Fbx {
                        "FBX"
                    } else {
                        "glTF"
                    },
                    build + gathered,
                    limits.answer_bytes
                )));
            }
            let mut plan = Plan::whole(
                &prepared,
                req.format,
                shaper,
                frames_out,
                &span,
                build + gathered,
                None,
            );
            if let Writer::Whole(w) = &mut plan.writer {
                w.space = (
                    transform
                        .metres_per_unit
                        .unwrap_or(onto.map_or(prepared.metres_per_unit, |t| t.metres_per_unit)),
                    transform.up.unwrap_or(Axis::Y),
                );
                w.character = character;
                w.read_limits = crate::motion::formats::ReadLimits::from(limits);
            }
            plan
        }
        format if onto.is_some() => {
            // Positions of the target's joints: channels decoded, shaped onto it, placed.
            let rig = channels_rig(store, &prepared).await?;
            let shaper =
                Shaper::channels(&prepared, rig.joints(), &transform, frames, onto, req.feet)?
                    .limited(frames_out);
            let names: Vec<String> = shaper
                .joints()
                .map(|j| j.iter().map(|j| j.name.clone()).collect())
                .unwrap_or_default();
            let selected = req
                .points
                .as_deref()
                .map(|want| super::retarget::joint_indices(&names, want))
                .transpose()?;
            let kept: Vec<String> = selected.as_ref().map_or_else(
                || names.clone(),
                |ix| ix.iter().map(|&i| names[i].clone()).collect(),
            );
            let span = Span {
                chunk_frames: grow(chunk_frames),
                part_frames: grow(part_frames),
                ..span
            };
            // In the target's unit unless another is asked for.
            let shaped = Options {
                metres_per_unit: transform
                    .metres_per_unit
                    .or(onto.map(|t| t.metres_per_unit)),
                ..transform
            };
            let mut plan =
                Plan::points(&prepared, format, Some(&kept), limits, &span, Some(&shaped))?;
            if let Writer::Points { selected, .. } = &mut plan.writer {
                *selected = None;
            }
            plan.decode_bytes = chunk_frames
                * (rig.channel_count() as u64 * CHANNEL_BYTES
                    + prepared.point_names.len() as u64 * 12);
            plan.shaper = Some(shaper.as_positions(selected));
            plan
        }
        format if transform.is_identity() => Plan::points(
            &prepared,
            format,
            req.points.as_deref(),
            limits,
            &span,
            None,
        )?,
        format => {
            let selected = req
                .points
                .as_deref()
                .map(|n| point_indices(&prepared, n))
                .transpose()?;
            let shaper =
                Shaper::points(&prepared, &transform, frames, selected)?.limited(frames_out);
            let names = shaper.point_names(&prepared);
            let span = Span {
                chunk_frames: grow(chunk_frames),
                part_frames: grow(part_frames),
                ..span
            };
            let mut plan = Plan::points(
                &prepared,
                format,
                Some(&names),
                limits,
                &span,
                Some(&transform),
            )?;
            // Every point is decoded (root motion follows the root) and the asked-for kept.
            if let Writer::Points { selected, .. } = &mut plan.writer {
                *selected = None;
            }
            plan.decode_bytes = chunk_frames * prepared.point_names.len() as u64 * 12 * 3;
            plan.shaper = Some(shaper);
            plan
        }
    };
    let mut head = Vec::new();
    let length = match &mut writer {
        Writer::Points { writer, .. } => {
            writer.head(&mut head);
            writer.exact_len()
        }
        Writer::Channels { writer, .. } => {
            writer.head(&mut head);
            None
        }
        Writer::Whole(_) => None,
    };
    // A whole file (glTF, C3D) is refused past the answer limit before it is built.
    let len_bound = match &writer {
        Writer::Whole(_) => limits.answer_bytes,
        _ => length.unwrap_or(
            (head.len() as u64 + frames_out as u64 * frame_bytes).saturating_add(TAIL_BYTES as u64),
        ),
    };
    // Output in flight: a few pieces, or the whole answer if it is smaller. A piece is a
    // frame past its size at most (the head is the first piece's start).
    let piece = (PIECE_BYTES as u64).max(head.len() as u64) + frame_bytes + TAIL_BYTES as u64;
    let output =
        (PIECES_IN_FLIGHT * piece).min(head.len() as u64 + frames_out as u64 * frame_bytes + piece);
    let payloads = PAYLOAD_BATCH.min(all_payloads).max(max_payload);
    let bound = 2 * decode_bytes + block_bytes + payloads + output;
    let fps = transform.fps.unwrap_or(prepared.fps);
    let metres_per_unit = transform
        .metres_per_unit
        .unwrap_or(onto.map_or(prepared.metres_per_unit, |t| t.metres_per_unit));
    Ok(Planned {
        prepared,
        start,
        end,
        chunks,
        frames_out,
        fps,
        metres_per_unit,
        writer,
        points,
        shaper,
        block_bytes,
        frame_bytes,
        head,
        length,
        len_bound,
        bound,
    })
}

/// Where an answer lies in its take, for [`Plan::points`].
struct Span<'a> {
    id: &'a str,
    start: usize,
    end: usize,
    /// The answer's frames: `end - start`, or as many as resampling makes of them.
    frames: usize,
    /// The frames of the largest chunk the range lies in, and the most of one in the range.
    chunk_frames: u64,
    part_frames: u64,
}

/// How an answer will be written, and what its decoding holds at most.
struct Plan {
    writer: Writer,
    points: Option<usize>,
    /// One chunk decoded, and the part of it the answer keeps, bytes.
    decode_bytes: u64,
    block_bytes: u64,
    /// The most bytes one frame of output takes.
    frame_bytes: u64,
    shaper: Option<Shaper>,
}

impl Plan {
    /// Positions of every point or of the named ones, checked against the answer limit.
    /// With `shaped` (the transforms asked for), `names` are the shaped frame's points and
    /// the answer's rate and unit are the transforms'.
    fn points(
        prepared: &Prepared,
        format: Format,
        names: Option<&[String]>,
        limits: &Limits,
        span: &Span<'_>,
        shaped: Option<&Options>,
    ) -> Result<Plan> {
        let (selected, names) = match (shaped, names) {
            (Some(_), Some(n)) => (None, n.into()),
            (_, None) => (None, prepared.point_names.clone()),
            (None, Some(n)) => {
                let ix = point_indices(prepared, n)?;
                let names = ix
                    .iter()
                    .map(|&i| prepared.point_names[i].clone())
                    .collect();
                (Some(ix), names)
            }
        };
        let frames = span.frames;
        check_size(frames, names.len(), limits)?;
        let n = names.len();
        let metres_per_unit = shaped
            .and_then(|o| o.metres_per_unit)
            .unwrap_or(prepared.metres_per_unit);
        let unit = Unit::new(metres_per_unit, UnitSource::Declared)
            .map_err(|e| Error::Corrupt(format!("stored take {}: {e}", span.id)))?;
        let shape = Shape {
            fps: shaped.and_then(|o| o.fps).unwrap_or(prepared.fps),
            unit,
            point_names: names,
            frames,
        };
        let mut fields = serde_json::Map::new();
        if format == Format::Json {
            fields.insert("id".into(), span.id.into());
            fields.insert("start".into(), span.start.into());
            fields.insert("end".into(), span.end.into());
            fields.insert("metres_per_unit".into(), metres_per_unit.into());
        }
        let writer =
            frame_writer(format, shape, fields).map_err(|e| Error::Unsatisfiable(e.to_string()))?;
        Ok(Plan {
            frame_bytes: writer.frame_bytes() as u64,
            writer: Writer::Points { writer, selected },
            points: Some(n),
            decode_bytes: span.chunk_frames * prepared.point_names.len() as u64 * 12,
            block_bytes: span.part_frames * n as u64 * 12,
            shaper: None,
        })
    }

    /// A skeleton's channels, as BVH (shaped by `shaper` when transforms are asked for).
    fn channels(
        rig: &codec::Skeleton,
        prepared: &Prepared,
        shaper: Option<Shaper>,
        frames: usize,
        chunk_frames: u64,
        part_frames: u64,
    ) -> Plan {
        let channels = rig.channel_count();
        let (joints, fps) = match &shaper {
            Some(s) => (s.joints().unwrap_or(rig.joints()).to_vec(), s.fps(prepared)),
            None => (rig.joints().to_vec(), prepared.fps),
        };
        let out_channels: u64 = joints.iter().map(|j| j.channels.len() as u64).sum();
        let writer = ChannelWriter::new(joints, fps, frames);
        // A value and how it was printed (`bvh-lossless`), per channel; and the positions
        // a decoder may work through.
        let per_frame = channels as u64 * CHANNEL_BYTES;
        let positions = prepared.point_names.len() as u64 * 12;
        Plan {
            frame_bytes: writer.frame_bytes() as u64,
            writer: Writer::Channels { writer, channels },
            points: None,
            decode_bytes: chunk_frames * (per_frame + positions),
            block_bytes: part_frames * out_channels.max(channels as u64) * CHANNEL_BYTES,
            shaper,
        }
    }

    /// A glTF of the shaped frames, gathered whole; `bytes` is what gathering and writing
    /// hold.
    fn whole(
        prepared: &Prepared,
        format: Format,
        shaper: Shaper,
        frames: usize,
        span: &Span<'_>,
        bytes: u64,
        c3d: Option<C3dParts>,
    ) -> Plan {
        let header = prepared.reader.header();
        // A chunk's positions, or its channels shaped onto a target (which may have more).
        let in_width =
            (prepared.point_names.len() as u64 * 12).max(shaper.width() as u64 * CHANNEL_BYTES);
        let whole = Whole {
            format,
            joints: shaper.joints().map(<[_]>::to_vec),
            names: shaper.point_names(prepared),
            values: Vec::new(),
            frames,
            extras: serde_json::json!({
                "mocapstore": {
                    "id": prepared.id,
                    "codec": header.codec.to_string(),
                    "bound": prepared.bound,
                }
            }),
            name: prepared.name.clone(),
            fps: shaper.fps(prepared),
            c3d,
            space: (prepared.metres_per_unit, Axis::Y),
            character: None,
            read_limits: crate::motion::formats::ReadLimits::default(),
            _held: None,
        };
        Plan {
            writer: Writer::Whole(Box::new(whole)),
            points: None,
            // A chunk decoded as positions (or channels, which take fewer bytes than the
            // positions a skeleton decoder works through).
            decode_bytes: span.chunk_frames * in_width * 2,
            block_bytes: bytes,
            frame_bytes: 0,
            shaper: Some(shaper),
        }
    }
}

/// An answer of `frames` of `points` within [`Limits::answer_samples`], or a 400 saying so.
fn check_size(frames: usize, points: usize, limits: &Limits) -> Result<()> {
    let samples = (frames as u64).saturating_mul(points as u64);
    crate::limits::check(
        "the answer's samples (frames × points)",
        samples,
        limits.answer_samples,
    )
    .map_err(|why| Error::InvalidRequest(format!("{why}: ask for a shorter range or fewer points")))
}

/// Bytes a decoded channel value takes with how it was printed.
const CHANNEL_BYTES: u64 = 8 + 16;

/// The indices of the named points: a 400 naming the first that is not in the take, or
/// that is named twice (each repeat would be a whole column more of output).
fn point_indices(prepared: &Prepared, names: &[String]) -> Result<Vec<usize>> {
    let mut seen = std::collections::HashSet::with_capacity(names.len());
    if let Some(twice) = names.iter().find(|n| !seen.insert(n.as_str())) {
        return Err(Error::InvalidRequest(format!(
            "point {twice:?} is named more than once in points"
        )));
    }
    prepared.point_indices(names)
}

/// The skeleton a take's channels decode with, if its codec keeps them; `Unsatisfiable`,
/// saying why and which codecs would, if not.
async fn channels_rig(store: &Store, prepared: &Prepared) -> Result<Arc<codec::Skeleton>> {
    let header = prepared.reader.header();
    let keeps = codec::codec(header.codec).is_ok_and(|c| c.codes_channels());
    let id = &prepared.id;
    match (keeps, header.rig) {
        (true, Some(h)) => super::skeletons::load(store, &hex(&h)).await,
        (true, None) => Err(Error::Corrupt(format!(
            "stored take {id}: a codec that keeps channels names no skeleton"
        ))),
        (false, _) => {
            let keepers: Vec<String> = codec::available()
                .into_iter()
                .filter(|&c| codec::codec(c).is_ok_and(|k| k.codes_channels()))
                .map(|c| c.to_string())
                .collect();
            let why = if !prepared.skeleton {
                "the take is point data (it has no skeleton)".to_string()
            } else {
                format!(
                    "the take was coded with {}, which keeps joint positions only; codecs \
                     that keep the animation: {} (ingest with keep=animation, the default for \
                     skeleton takes)",
                    header.codec,
                    keepers.join(", ")
                )
            };
            Err(Error::Unsatisfiable(format!("no BVH for take {id}: {why}")))
        }
    }
}

impl Answer {
    /// Frames in the answer.
    pub fn frames(&self) -> usize {
        self.end - self.start
    }

    /// The coding this answer reads (and the body's revision its transforms read): what
    /// anything computed from it is kept by.
    pub fn stamp(&self) -> super::prepared::Stamp {
        self.prepared.stamp
    }

    /// Read as one of many takes read whole (an export, motion statistics): the chunks it
    /// decodes are not kept in the server's cache, so that a pass over a library does not
    /// evict what range requests keep hot. Chunks cached already are still read from it.
    pub fn bulk(mut self) -> Answer {
        self.cache = false;
        self
    }

    /// The next decoded and shaped frames of a positions answer (frames × points × 3, NaN
    /// where missing), not written: what reads the values themselves ([`super::motion_stats`])
    /// take instead of [`Answer::next`]. `None` once every frame is given. Counted in the
    /// answer's reservation while the returned [`Held`] lives.
    pub async fn next_positions(&mut self) -> Result<Option<(Vec<f32>, Held)>> {
        if !matches!(self.writer, Writer::Points { .. }) {
            return Err(Error::Internal(format!(
                "{} answers are written, not read as positions",
                self.format.name()
            )));
        }
        loop {
            if let Some(block) = self.block.take() {
                self.frames_left = self
                    .frames_left
                    .saturating_sub(block.frames - block.written);
                let width = self.points.unwrap_or(0) * 3;
                let v = match block.data {
                    Decoded::Positions(mut v) => {
                        v.drain(..block.written * width);
                        v
                    }
                    Decoded::Cached { chunk, first } => {
                        let rows = first + block.written..first + block.frames;
                        chunk[rows.start * width..rows.end * width].to_vec()
                    }
                    Decoded::Channels(_) => unreachable!("a points answer decodes positions"),
                };
                let held = self.reservation.hold(v.capacity() as u64 * 4);
                drop(block._held);
                return Ok(Some((v, held)));
            }
            if self.next_chunk >= self.last_chunk {
                return Ok(None);
            }
            self.decode_next().await?;
        }
    }

    /// The next piece of output; `None` once the answer is whole.
    pub async fn next(&mut self) -> Result<Option<Bytes>> {
        loop {
            if self.pending.len() >= PIECE_BYTES {
                return Ok(Some(self.hand_on()));
            }
            if self.block.is_some() {
                self.write_some();
                continue;
            }
            if self.next_chunk < self.last_chunk {
                self.decode_next().await?;
                continue;
            }
            if !self.tail_done {
                self.tail_done = true;
                match &mut self.writer {
                    Writer::Points { writer, .. } => writer.tail(&mut self.pending),
                    Writer::Whole(w) if w.c3d.is_some() => {
                        let bytes = self.c3d_file().await?;
                        if let Writer::Whole(w) = &mut self.writer {
                            w._held = None;
                        }
                        self.pending = bytes;
                    }
                    Writer::Whole(w) => {
                        let file = w.file();
                        let bytes = blocking(move || file.write()).await??;
                        // The file is held as the piece it is handed on in from now.
                        w._held = None;
                        self.pending = bytes;
                    }
                    Writer::Channels { .. } => {}
                }
            }
            return Ok((!self.pending.is_empty()).then(|| self.hand_on()));
        }
    }

    /// What is pending, as a piece that counts as held until it is written.
    fn hand_on(&mut self) -> Bytes {
        let fresh = self.fresh_piece();
        let data = std::mem::replace(&mut self.pending, fresh);
        self.reservation.hand_on(data)
    }

    /// An empty piece with room for what it may hold: a piece's worth, or what is left of
    /// the answer (and its tail) if that is less.
    fn fresh_piece(&self) -> Vec<u8> {
        let room = (self.frames_left * self.frame_bytes).min(PIECE_BYTES);
        Vec::with_capacity(room + self.frame_bytes + TAIL_BYTES)
    }

    /// Write frames of the current block until a piece is full or the block is done.
    fn write_some(&mut self) {
        let Some(block) = &mut self.block else { return };
        let (per_frame, width) = match &self.writer {
            Writer::Points { writer, .. } => (writer.frame_bytes(), self.points.unwrap_or(0) * 3),
            Writer::Channels { writer, .. } => (writer.frame_bytes(), writer.channels()),
            Writer::Whole(_) => unreachable!("a glTF answer is gathered, not written in blocks"),
        };
        let room = PIECE_BYTES.saturating_sub(self.pending.len());
        let n = (room / per_frame.max(1)).clamp(1, block.frames - block.written);
        let (a, b) = (block.written, block.written + n);
        match (&mut self.writer, &block.data) {
            (Writer::Points { writer, .. }, Decoded::Positions(v)) => {
                writer.frames(n, &v[a * width..b * width], &mut self.pending);
            }
            (Writer::Points { writer, .. }, Decoded::Cached { chunk, first }) => {
                let rows = &chunk[(first + a) * width..(first + b) * width];
                writer.frames(n, rows, &mut self.pending);
            }
            (Writer::Channels { writer, .. }, Decoded::Channels(c)) => {
                writer.frames(&c.values, c.printed.as_ref(), a..b, &mut self.pending);
            }
            _ => unreachable!("a block is decoded for its writer"),
        }
        block.written = b;
        self.frames_left -= n;
        if block.written == block.frames {
            self.block = None;
        }
    }

    /// Decode the part of the next chunk that lies in the range.
    async fn decode_next(&mut self) -> Result<()> {
        let i = self.next_chunk;
        self.next_chunk += 1;
        let header = self.prepared.reader.header();
        let r = header.chunks[i].frame_range();
        let part = r.start.max(self.start)..r.end.min(self.end);
        let full = r.len() * header.points as usize * 3 * 4;
        // Positions (of the selected points, or all when shaped), or channels (how many).
        let selected = match (&self.writer, &self.shaper) {
            // Channels decoded, shaped onto another skeleton and placed.
            (Writer::Points { .. }, Some(Shaper::Channels { .. })) => None,
            (Writer::Points { selected, .. }, _) => Some(selected.clone()),
            (Writer::Whole(_), Some(Shaper::Points { .. })) => Some(None),
            _ => None,
        };
        let channels = match (&self.writer, &self.shaper) {
            (Writer::Channels { channels, .. }, _) => *channels,
            (_, Some(s @ Shaper::Channels { .. })) => s.channels_in(),
            _ => 0,
        };
        let frames = part.len();
        debug_assert!(frames > 0, "a chunk the range lies in holds some of it");
        // What decoding holds (the payload, the chunk decoded, the decoder's copy) is counted
        // until the decode ends, even if this answer is dropped meanwhile (its client went
        // away): the blocking pool finishes the work, and its memory stays reserved.
        let block = match selected {
            Some(selected) => {
                let cached = self.caches.chunks.get(&self.prepared, i);
                let part_bytes =
                    frames * selected.as_ref().map_or(header.points as usize, Vec::len) * 12;
                if let (Some(d), None, Writer::Points { .. }) =
                    (&cached, &self.shaper, &self.writer)
                {
                    if part_bytes <= INLINE_COPY_BYTES {
                        // Decoded already and nothing to shape: the part is a copy, made here
                        // rather than on the blocking pool (the hop there and back costs more
                        // than the copy).
                        let width = header.points as usize * 3;
                        if d.len() != r.len() * width {
                            return Err(Error::Internal(format!(
                                "take {}: cached chunk {i} holds {} values, not {}",
                                self.id,
                                d.len(),
                                r.len() * width
                            )));
                        }
                        let (data, held) = match selected {
                            // Every point: the writer reads the cached frames themselves.
                            None => (
                                Decoded::Cached {
                                    chunk: d.clone(),
                                    first: part.start - r.start,
                                },
                                self.reservation.hold(0),
                            ),
                            Some(ix) => {
                                let one = One::new(i, OneChunk::Decoded(d.clone()), false);
                                let held = self.reservation.hold(part_bytes as u64);
                                let data = self.prepared.reader.read(part, Some(&ix), &one)?;
                                (Decoded::Positions(data), held)
                            }
                        };
                        self.block = Some(Block {
                            frames,
                            written: 0,
                            data,
                            _held: held,
                        });
                        return Ok(());
                    }
                }
                let (chunk, payload_held) = match cached {
                    Some(d) => (OneChunk::Decoded(d), None),
                    None => {
                        let (payload, held) = self.payload(i).await?;
                        (OneChunk::Stored(payload), Some(held))
                    }
                };
                let keep = self.cache && matches!(chunk, OneChunk::Stored(_));
                let working = self.reservation.hold(2 * full as u64);
                let p = self.prepared.clone();
                // The transforms run beside the decode, on the blocking pool (resampling a
                // chunk is a pass over every sample); the shaper's state goes with them.
                let mut shaper = self.shaper.take();
                let (data, fresh, shaper) = blocking(move || {
                    let _held = (working, payload_held);
                    let one = One::new(i, chunk, keep);
                    let data =
                        p.reader
                            .read(part, selected.as_deref(), &one)
                            .map(|d| match &mut shaper {
                                Some(s) => s.positions(&d, frames),
                                None => (d, frames),
                            });
                    (data, one.kept.into_inner().ok().flatten(), shaper)
                })
                .await?;
                if let Some(fresh) = fresh {
                    self.caches.chunks.insert(&self.prepared, i, fresh);
                }
                let (data, frames) = data?;
                self.shaper = shaper;
                let held = self.reservation.hold(data.capacity() as u64 * 4);
                Block {
                    frames,
                    written: 0,
                    data: Decoded::Positions(data),
                    _held: held,
                }
            }
            None => {
                let (payload, payload_held) = self.payload(i).await?;
                // A frame's channels decoded, or shaped onto another skeleton's (more when
                // it has more).
                let width = channels.max(self.shaper.as_ref().map_or(0, Shaper::width));
                let working = self
                    .reservation
                    .hold(r.len() as u64 * (width as u64 * CHANNEL_BYTES) + full as u64);
                let p = self.prepared.clone();
                let mut shaper = self.shaper.take();
                let (decoded, shaper) = blocking(move || {
                    let _held = (working, payload_held);
                    let one = One::new(i, OneChunk::Stored(payload), false);
                    let decoded = p.reader.read_channels(part, channels, &one).map(|d| {
                        match &mut shaper {
                            // Shaped values are new values: nothing was printed for them.
                            Some(s) => codec::skeleton::Channels {
                                values: s.channel_values(&d.values),
                                printed: None,
                            },
                            None => d,
                        }
                    });
                    (decoded, shaper)
                })
                .await?;
                let decoded = decoded?;
                let frames = match &shaper {
                    Some(s) => decoded.values.len() / s.width().max(1),
                    None => frames,
                };
                let mut shaper = shaper;
                if let Some((positions, frames)) =
                    shaper.as_mut().and_then(|s| s.placed(&decoded.values))
                {
                    self.shaper = shaper;
                    let held = self.reservation.hold(positions.capacity() as u64 * 4);
                    self.block = (frames > 0).then_some(Block {
                        frames,
                        written: 0,
                        data: Decoded::Positions(positions),
                        _held: held,
                    });
                    return Ok(());
                }
                self.shaper = shaper;
                let bytes = decoded.values.capacity() * 8
                    + decoded
                        .printed
                        .as_ref()
                        .map_or(0, |p| p.values.capacity() * 16);
                let held = self.reservation.hold(bytes as u64);
                Block {
                    frames,
                    written: 0,
                    data: Decoded::Channels(decoded),
                    _held: held,
                }
            }
        };
        if let Writer::Whole(w) = &mut self.writer {
            // Gathered: counted in the reservation's gathering share from the start.
            match block.data {
                Decoded::Positions(v) => w.values.extend(v.iter().map(|&x| f64::from(x))),
                Decoded::Cached { .. } => {
                    unreachable!("only points answers read cached frames in place")
                }
                Decoded::Channels(c) => w.values.extend_from_slice(&c.values),
            }
            self.frames_left = self.frames_left.saturating_sub(block.frames);
            return Ok(());
        }
        if block.frames > 0 {
            self.block = Some(block);
        }
        Ok(())
    }

    /// The C3D file of a gathered answer: its points, the take's analog channels over the
    /// range (in frames of the answer's rate), events and parameters.
    async fn c3d_file(&mut self) -> Result<Vec<u8>> {
        let Writer::Whole(w) = &mut self.writer else {
            unreachable!("a C3D answer is gathered")
        };
        let parts = w.c3d.take().expect("a C3D answer has its parts");
        let values = std::mem::take(&mut w.values);
        let (names, fps, frames) = (w.names.clone(), w.fps, w.frames);
        let analog = match &parts.analog {
            None => None,
            Some((d, per_frame)) => {
                let a =
                    super::analog::range_of(&self.store, &self.id, d, self.start, self.end).await?;
                Some(a.with_per_frame(*per_frame, frames))
            }
        };
        let parameters = super::analog::parameters(&self.store, &self.id).await?;
        let outputs = match super::outputs::of(&self.store, &self.id).await? {
            Some(o) if o.frames() >= self.end => {
                let o = o
                    .rows(self.start, self.end)
                    .resampled(self.prepared.fps, fps);
                if o.frames() != frames {
                    return Err(Error::Internal(format!(
                        "take {}: {} frames of model outputs for {frames} frames",
                        self.id,
                        o.frames()
                    )));
                }
                Some(o)
            }
            Some(o) => {
                return Err(Error::Corrupt(format!(
                    "take {}: {} frames of model outputs, fewer than its frames",
                    self.id,
                    o.frames()
                )))
            }
            None => None,
        };
        let id = self.id.clone();
        blocking(move || -> Result<Vec<u8>> {
            use crate::motion::formats::c3d::write;
            let unit = Unit::new(parts.metres_per_unit, UnitSource::Declared)
                .map_err(|e| Error::Corrupt(format!("take {id}: {e}")))?;
            let points: Vec<f32> = values.iter().map(|&v| v as f32).collect();
            let motion = if names.is_empty() {
                crate::motion::Motion::without_points(fps, unit, frames)
            } else {
                crate::motion::Motion::new(fps, unit, names, points, None)
            }
            .map_err(|e| Error::Corrupt(format!("take {id}: {e}")))?;
            write::write(&write::Out {
                motion: &motion,
                analog: analog.as_ref(),
                outputs: outputs.as_ref(),
                parameters: parameters.as_ref(),
                first_frame: parts.first_frame,
            })
            .map_err(|e| Error::Unsatisfiable(e.to_string()))
        })
        .await?
    }

    /// The stored payload of chunk `i` (the next one), and what counts it as held, reading
    /// ahead a batch of payloads when none is left.
    async fn payload(&mut self, i: usize) -> Result<(Vec<u8>, Held)> {
        // Payloads read ahead of chunks that came from the cache instead are not needed.
        while self.batch.front().is_some_and(|(r, _)| r.idx < i as i64) {
            self.batch.pop_front();
        }
        if self.batch.is_empty() {
            let chunks = &self.prepared.reader.header().chunks;
            let mut end = i + 1;
            let mut bytes = u64::from(chunks[i].len);
            while end < self.last_chunk && bytes + u64::from(chunks[end].len) <= PAYLOAD_BATCH {
                bytes += u64::from(chunks[end].len);
                end += 1;
            }
            let rows = self.store.chunks(&self.id, i as i64, end as i64).await?;
            if rows.len() != end - i {
                // Deleted since its reader was checked: say so (404), or else that it changed.
                super::fetch::take(&self.store, &self.id).await?;
                return Err(Error::Internal(format!(
                    "take {} is missing chunks {i}..{end}",
                    self.id
                )));
            }
            for row in rows {
                let held = self.reservation.hold(row.payload.capacity() as u64);
                self.batch.push_back((row, held));
            }
        }
        match self.batch.pop_front() {
            Some((row, held)) if row.idx == i as i64 => Ok((row.payload, held)),
            _ => Err(Error::Internal(format!(
                "take {}: chunk {i} was not read in order",
                self.id
            ))),
        }
    }
}

/// One chunk as a [`ChunkSource`]: decoded already (from the cache) or its stored payload;
/// with `keep`, the whole chunk decoded from the payload is kept for the cache.
struct One {
    index: usize,
    chunk: OneChunk,
    keep: bool,
    kept: Mutex<Option<Arc<Vec<f32>>>>,
}

enum OneChunk {
    Decoded(Arc<Vec<f32>>),
    Stored(Vec<u8>),
}

impl One {
    fn new(index: usize, chunk: OneChunk, keep: bool) -> One {
        One {
            index,
            chunk,
            keep,
            kept: Mutex::new(None),
        }
    }
}

impl ChunkSource for One {
    fn chunk(&self, index: usize) -> codec::Result<Chunk<'_>> {
        if index != self.index {
            return Err(codec::Error::Fault(format!("chunk {index} was not read")));
        }
        Ok(match &self.chunk {
            OneChunk::Decoded(d) => Chunk::Decoded(d.clone()),
            OneChunk::Stored(p) => Chunk::Stored(p),
        })
    }

    fn keeps(&self) -> bool {
        self.keep
    }

    fn keep(&self, _index: usize, decoded: Arc<Vec<f32>>) {
        if let Ok(mut k) = self.kept.lock() {
            *k = Some(decoded);
        }
    }
}
