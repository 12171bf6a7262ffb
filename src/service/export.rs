//! A library as files people open: every take of a selection in one format, through the one
//! read path ([`super::answer`], with its transforms), named from the take's name and made
//! unique, with a `manifest.csv` — streamed as one ZIP ([`open`], `GET /v1/export`), or
//! written file by file by `mocapstore export --format` (which names and lists them with
//! [`plan`] and [`Entry`], so both give the same names and manifest).
//!
//! # What an export holds
//! One take's answer at a time (its own reservation, taken beside the export's, so a take
//! may be as large as a request of its own), the ZIP writer's compressor and a few pieces of
//! output ([`ZIP_BYTES`]), and per take its manifest entry and its record in the ZIP's
//! central directory (a few hundred bytes), reserved before anything is written. Nothing
//! grows with the takes' lengths; the per-take records grow with their number, so a
//! selection whose records do not fit the caller's share is refused before it starts
//! (narrow it by library, tag or name). Takes are listed a page at a time.
//!
//! # What a client gets
//! Entries are `library/name.ext`, in the order the takes were stored; a name used already
//! (ignoring case, as macOS and Windows do) gets `_2`, `_3`… Each entry's modification time
//! is its take's creation time, so exporting the same selection twice gives the same bytes.
//! A take that cannot be written in the format (BVH of a marker take, a glTF too long for one
//! answer) or cannot be read (a damaged chunk, a record that does not parse) is not an
//! error: its manifest line says why in `skipped` and the export goes on. What stops an
//! export is the database or the server failing, or a take failing once its file is under
//! way (the ZIP is then cut short, without its central directory, which readers refuse).
//! `manifest.csv` comes last, when every file's size and BLAKE3 are known.

use std::collections::HashSet;
use std::io::Write;
use std::sync::{Arc, Mutex};

use bytes::Bytes;
use serde::{Deserialize, Serialize};
use zip::write::{SimpleFileOptions, StreamWriter};
use zip::{CompressionMethod, ZipWriter};

use super::access::Grant;
use super::answer::{
    self, points_written, RangeRequest, BUDGET_WAIT, PIECES_IN_FLIGHT, PIECE_BYTES,
};
use super::budget::{Budget, Held, Holder, Reservation};
use super::fetch::TimeRange;
use super::library::{Pages, TakeQuery};
use super::prepared::ReadCaches;
use super::take::Take;
use super::{blocking, Error, Result};
use crate::limits::Limits;
use crate::motion::formats::Format;
use crate::motion::transform::Options;
use crate::store::Store;

/// The manifest's file name, in the ZIP and in an export folder.
pub const MANIFEST: &str = "manifest.csv";

/// The manifest's columns, in order.
pub const COLUMNS: [&str; 19] = [
    "file",
    "id",
    "name",
    "library",
    "tags",
    "labels",
    "frames",
    "fps",
    "source_fps",
    "codec",
    "max_bound_mm",
    "mean_bound_mm",
    "max_error_mm",
    "mean_error_mm",
    "bytes",
    "blake3",
    "skipped",
    // After the columns of earlier versions, so that readers by position keep working.
    "metres_per_unit",
    "points",
];

/// What the ZIP writer holds beside the answer it writes: the deflate state (zlib's window,
/// hash chains and pending output are about 300 KiB) and output pieces in flight.
pub const ZIP_BYTES: u64 = (1 << 20) + PIECES_IN_FLIGHT * 2 * (PIECE_BYTES as u64 + (64 << 10));

/// Output is handed on once this much is written (an entry's end hands on what is left).
const OUT_PIECE: usize = 64 << 10;

/// A library export, parsed: which takes, which format, which transforms.
#[derive(Debug, Clone)]
pub struct ExportRequest {
    /// Which takes, among those `grant` reaches.
    pub takes: TakeQuery,
    pub grant: Grant,
    pub format: Format,
    pub transform: Options,
    /// The skeleton every take is put on (`skeleton=`), and what is done to its feet.
    pub onto: Option<super::retarget::Onto>,
    pub feet: super::retarget::Feet,
}

/// One take's line in the manifest: the take, where its file is, and what was written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    /// The file's path in the export, `library/name.ext`.
    pub file: String,
    pub id: String,
    pub name: String,
    pub library: String,
    pub tags: Vec<String>,
    /// The take's labels (a JSON object in the manifest, empty when it has none).
    #[serde(default)]
    pub labels: crate::labels::Labels,
    /// The file's frames and their rate (resampled, if asked); the take's own until written.
    pub frames: usize,
    pub fps: f64,
    pub source_fps: f64,
    /// The file's unit (the take's, or `unit=`'s), and the names of its points in order
    /// (none for BVH, which names its joints itself): what reading an `.npy` or `.json`
    /// back needs without the server.
    #[serde(default)]
    pub metres_per_unit: f64,
    #[serde(default)]
    pub points: Vec<String>,
    pub codec: String,
    pub max_bound_mm: f64,
    pub mean_bound_mm: Option<f64>,
    /// The errors the take measured when it was stored, against its original.
    pub max_error_mm: f64,
    pub mean_error_mm: f64,
    /// The file's size and BLAKE3 (hex), once written.
    pub bytes: Option<u64>,
    pub blake3: Option<String>,
    /// Why the take has no file in this format, if it has none.
    pub skipped: Option<String>,
    /// When the take was stored (ms since the epoch): the file's modification time.
    pub created_at: i64,
}

impl Entry {
    pub fn of(take: &Take, file: String) -> Entry {
        Entry {
            file,
            id: take.id.clone(),
            name: take.name.clone(),
            library: take.library.clone(),
            tags: take.tags.clone(),
            labels: take.labels.clone(),
            frames: take.frames,
            fps: take.fps,
            source_fps: take.fps,
            metres_per_unit: take.metres_per_unit,
            // Counted in the manifest's reservation now; the written file's once written.
            points: take.meta.point_names.clone(),
            codec: take.codec.to_string(),
            max_bound_mm: take.bound.max_mm(),
            mean_bound_mm: take.bound.mean_mm(),
            max_error_mm: take.max_mm,
            mean_error_mm: take.mean_mm,
            bytes: None,
            blake3: None,
            skipped: None,
            created_at: take.created_at,
        }
    }

    /// The entry of a take whose record could not be read: what its row says.
    fn unread(
        file: String,
        id: String,
        name: String,
        library: String,
        tags: Vec<String>,
        created_at: i64,
    ) -> Entry {
        Entry {
            file,
            id,
            name,
            library,
            tags,
            labels: Default::default(),
            frames: 0,
            fps: 0.0,
            source_fps: 0.0,
            metres_per_unit: 0.0,
            points: Vec::new(),
            codec: String::new(),
            max_bound_mm: 0.0,
            mean_bound_mm: None,
            max_error_mm: 0.0,
            mean_error_mm: 0.0,
            bytes: None,
            blake3: None,
            skipped: None,
            created_at,
        }
    }

    /// The manifest's line for this entry (CSV, RFC 4180 quoting, tags joined by `;`, labels
    /// as a JSON object; text
    /// a spreadsheet would run as a formula made inert: [`csv_text`]).
    pub fn csv_line(&self) -> String {
        let opt = |v: Option<String>| v.unwrap_or_default();
        let fields = [
            csv_text(&self.file),
            csv_text(&self.id),
            csv_text(&self.name),
            csv_text(&self.library),
            csv_text(&self.tags.join(";")),
            csv_text(&if self.labels.is_empty() {
                String::new()
            } else {
                serde_json::to_string(&self.labels).unwrap_or_default()
            }),
            self.frames.to_string(),
            self.fps.to_string(),
            self.source_fps.to_string(),
            csv_text(&self.codec),
            self.max_bound_mm.to_string(),
            opt(self.mean_bound_mm.map(|m| m.to_string())),
            self.max_error_mm.to_string(),
            self.mean_error_mm.to_string(),
            opt(self.bytes.map(|b| b.to_string())),
            opt(self.blake3.clone()),
            csv_text(&opt(self.skipped.clone())),
            self.metres_per_unit.to_string(),
            // A take with no file names no points.
            csv_text(&if self.points.is_empty() || self.skipped.is_some() {
                String::new()
            } else {
                serde_json::to_string(&self.points).unwrap_or_default()
            }),
        ];
        // Text is encoded above; numbers and hex hashes need no quotes.
        let mut line = fields.join(",");
        line.push_str("\r\n");
        line
    }
}

/// The manifest's header line.
pub fn manifest_head() -> String {
    let mut head = COLUMNS.join(",");
    head.push_str("\r\n");
    head
}

/// One CSV field, quoted where it must be (a comma, quote or line break in it).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\r', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// A text field of the manifest: one a spreadsheet would run as a formula (it starts with
/// `=`, `+`, `-`, `@`, a tab or a carriage return: a take named `=cmd|'/C calc'!A0`) gets a
/// `'` before it and is always quoted, as OWASP's advice on CSV injection has it; any other
/// is quoted where CSV must ([`csv_field`]).
fn csv_text(s: &str) -> String {
    if s.starts_with(['=', '+', '-', '@', '\t', '\r']) {
        format!("\"'{}\"", s.replace('"', "\"\""))
    } else {
        csv_field(s)
    }
}

/// A file-name-safe form of a name: letters and digits of any script, `.`, `_` and `-`;
/// anything else becomes `_`. Never empty, never hidden (a leading dot), never a name
/// Windows reserves for a device, at most 80 characters.
pub fn safe(name: &str) -> String {
    let s: String = name
        .trim()
        .chars()
        .map(|c| {
            if c.is_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .take(80)
        .collect();
    let stem = s.split('.').next().unwrap_or("").to_ascii_uppercase();
    let device = matches!(stem.as_str(), "CON" | "PRN" | "AUX" | "NUL")
        || (stem.len() == 4
            && (stem.starts_with("COM") || stem.starts_with("LPT"))
            && stem.ends_with(|c: char| c.is_ascii_digit()));
    if s.is_empty() || s.starts_with('.') || device {
        format!("_{s}")
    } else {
        s
    }
}

/// Unique file names for a selection's takes.
#[derive(Default)]
pub struct Names {
    used: HashSet<String>,
}

impl Names {
    /// `library/name.ext` for a take (library `_` when it has none), made unique ignoring
    /// case with `_2`, `_3`…
    pub fn file(&mut self, library: &str, name: &str, ext: &str) -> String {
        let folder = if library.trim().is_empty() {
            "_".to_string()
        } else {
            safe(library)
        };
        let stem = safe(name);
        let mut n = 1;
        loop {
            let file = if n == 1 {
                format!("{folder}/{stem}.{ext}")
            } else {
                format!("{folder}/{stem}_{n}.{ext}")
            };
            if self.used.insert(file.to_lowercase()) {
                return file;
            }
            n += 1;
        }
    }
}

/// The entries of a selection's takes, in the order given, each named for `format`.
pub fn plan(takes: &[Take], format: Format) -> Vec<Entry> {
    let mut names = Names::default();
    takes
        .iter()
        .map(|t| Entry::of(t, names.file(&t.library, &t.name, format.name())))
        .collect()
}

/// The manifest of `entries`: its header, then a line per entry.
pub fn manifest(entries: &[Entry]) -> String {
    let mut text = manifest_head();
    for e in entries {
        text.push_str(&e.csv_line());
    }
    text
}

/// What an entry adds to what an export holds, besides the entry itself: its manifest line
/// (reserved at its longest: a size, a digest and a reason to skip filled in later), and its
/// record in the ZIP writer's central directory, kept and then written at the end.
fn entry_bytes(e: &Entry) -> u64 {
    let line = e.csv_line().len() + 20 + 64 + SKIP_REASON_BYTES;
    let central = 2 * (e.file.len() + 128);
    (std::mem::size_of::<Entry>() + e.file.len() + 2 * line + central) as u64
}

/// The most of a reason to skip a take a manifest keeps (longer ones are cut).
const SKIP_REASON_BYTES: usize = 400;

/// A reason to skip a take, as the manifest keeps it.
fn reason(e: &Error) -> String {
    let mut why = e.to_string();
    if why.len() > SKIP_REASON_BYTES {
        let mut cut = SKIP_REASON_BYTES - 3;
        while !why.is_char_boundary(cut) {
            cut -= 1;
        }
        why.truncate(cut);
        why.push_str("...");
    }
    why
}

/// How every file is stored in the ZIP: deflated. Text shrinks to a third or less, and the
/// binary formats too (measured on the CMU and TRC corpus takes at 30 fps: GLB to 61 %, C3D
/// to 49 %: rest poses, repeated times and gaps repeat), at about 30 MB/s of one core.
const METHOD: CompressionMethod = CompressionMethod::Deflated;

/// What the ZIP is written into: bytes handed on as they come.
#[derive(Clone, Default)]
struct Sink(Arc<Mutex<Vec<u8>>>);

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().expect("sink lock").extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Sink {
    fn len(&self) -> usize {
        self.0.lock().expect("sink lock").len()
    }

    fn take(&self) -> Vec<u8> {
        let mut out = self.0.lock().expect("sink lock");
        std::mem::replace(&mut *out, Vec::with_capacity(OUT_PIECE + PIECE_BYTES))
    }
}

/// The ZIP writer and what it measures of the entry being written.
struct Zipper {
    zip: ZipWriter<StreamWriter<Sink>>,
    hasher: blake3::Hasher,
    written: u64,
}

impl Zipper {
    fn start(&mut self, name: &str, options: SimpleFileOptions) -> Result<()> {
        self.hasher = blake3::Hasher::new();
        self.written = 0;
        self.zip.start_file(name, options).map_err(zip_error)
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.hasher.update(bytes);
        self.written += bytes.len() as u64;
        self.zip
            .write_all(bytes)
            .map_err(|e| Error::Internal(format!("zip: {e}")))
    }
}

fn zip_error(e: zip::result::ZipError) -> Error {
    Error::Internal(format!("zip: {e}"))
}

/// An export, open: its pieces, taken with [`Export::next`].
pub struct Export {
    /// Takes in the export (written or skipped).
    pub takes: usize,
    store: Store,
    caches: Arc<ReadCaches>,
    budget: Arc<Budget>,
    limits: Limits,
    format: Format,
    transform: Options,
    onto: Option<Arc<super::retarget::Target>>,
    feet: super::retarget::Feet,
    entries: Vec<Entry>,
    /// The entry being written (its answer open), or the next to open.
    at: usize,
    answer: Option<answer::Answer>,
    /// A piece of the answer not yet all written into the ZIP, and how far it is.
    input: Option<(Bytes, usize)>,
    /// `None` while a write runs on the blocking pool, and once the archive is finished.
    zipper: Option<Zipper>,
    sink: Sink,
    reservation: Arc<Reservation>,
    _entries_held: Held,
    tail: Tail,
}

/// Check an export and open it, reserving what it will hold. The takes are listed and
/// named here; nothing is decoded yet.
pub async fn open(
    store: &Store,
    caches: &Arc<ReadCaches>,
    budget: &Arc<Budget>,
    holder: Holder,
    limits: &Limits,
    req: ExportRequest,
) -> Result<Export> {
    // The same for every take: refused once, not skipped take by take.
    let transform = answer::transform_for(req.format, req.transform)?;
    req.takes.check()?;
    let onto = match &req.onto {
        Some(onto) => {
            super::retarget::check_format(req.format)?;
            Some(super::retarget::target(store, &req.grant, onto).await?)
        }
        None if req.feet != super::retarget::Feet::Free => {
            return Err(Error::InvalidRequest(
                "feet=lock holds the feet of takes put on another skeleton: give skeleton= too"
                    .into(),
            ))
        }
        None => None,
    };
    let filter = req.takes.filter(&req.grant);
    // A page of takes at a time, each kept as its entry only.
    let mut entries = Vec::new();
    let mut names = Names::default();
    let mut pages = Pages::new(store, filter);
    while let Some(rows) = pages.next().await? {
        for row in rows {
            let file = names.file(&row.library, &row.name, req.format.name());
            let (id, name, library, tags) = (
                row.id.clone(),
                row.name.clone(),
                row.library.clone(),
                row.tags.clone(),
            );
            let created_at = row.created_at;
            entries.push(match super::fetch::parse(store, row).await {
                Ok(take) => Entry::of(&take, file),
                // A record that does not parse is reported, not a reason to stop.
                Err(e) => Entry {
                    skipped: Some(reason(&e)),
                    ..Entry::unread(file, id, name, library, tags, created_at)
                },
            });
        }
    }
    drop(names);
    let manifest: u64 = entries.iter().map(entry_bytes).sum();
    let mut reservation = budget.reservation(holder);
    reservation.grow_to(ZIP_BYTES + manifest).map_err(|r| {
        Error::Busy(format!(
            "{}; an export of {} takes holds {manifest} bytes of manifest: retry shortly, or \
             narrow it by library, tag or name",
            r.reason("library exports"),
            entries.len()
        ))
    })?;
    let reservation = Arc::new(reservation);
    let sink = Sink::default();
    Ok(Export {
        takes: entries.len(),
        store: store.clone(),
        caches: caches.clone(),
        budget: budget.clone(),
        limits: *limits,
        format: req.format,
        transform,
        onto,
        feet: req.feet,
        _entries_held: reservation.hold(manifest / 2),
        entries,
        at: 0,
        answer: None,
        input: None,
        zipper: Some(Zipper {
            zip: ZipWriter::new_stream(sink.clone()),
            hasher: blake3::Hasher::new(),
            written: 0,
        }),
        sink,
        reservation,
        tail: Tail::Takes,
    })
}

/// Where an export is past its takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tail {
    Takes,
    /// The manifest's entry is started and its text is the input.
    Manifest,
    /// The central directory is written: what is left in the sink is the last piece.
    Finished,
}

impl answer::Pieces for Export {
    fn next_piece(&mut self) -> impl std::future::Future<Output = Result<Option<Bytes>>> + Send {
        self.next()
    }

    fn what(&self) -> String {
        format!("library export of {} takes", self.takes)
    }
}

impl Export {
    /// The next piece of the ZIP; `None` once it is whole.
    pub async fn next(&mut self) -> Result<Option<Bytes>> {
        loop {
            if self.sink.len() >= OUT_PIECE {
                return Ok(Some(self.hand_on()));
            }
            if let Some((piece, at)) = self.input.take() {
                // Into the ZIP a slice at a time, so that what the sink holds stays a piece.
                let end = (at + PIECE_BYTES).min(piece.len());
                let part = piece.slice(at..end);
                self.zip(move |z| z.write(&part)).await?;
                if end < piece.len() {
                    self.input = Some((piece, end));
                }
                continue;
            }
            if let Some(a) = &mut self.answer {
                // Past its first piece a take cannot be skipped: its entry is under way.
                match a.next().await? {
                    Some(piece) => self.input = Some((piece, 0)),
                    None => {
                        self.answer = None;
                        let z = self.zipper.as_ref().ok_or_else(Self::finished)?;
                        let e = &mut self.entries[self.at];
                        e.bytes = Some(z.written);
                        e.blake3 = Some(z.hasher.finalize().to_hex().to_string());
                        self.at += 1;
                    }
                }
                continue;
            }
            if self.at < self.entries.len() {
                self.open_next().await?;
                continue;
            }
            match self.tail {
                Tail::Takes => {
                    let text = manifest(&self.entries);
                    let created = self.entries.iter().map(|e| e.created_at).max().unwrap_or(0);
                    let options = file_options(created, text.len() as u64);
                    self.zip(move |z| z.start(MANIFEST, options)).await?;
                    self.input = Some((Bytes::from(text), 0));
                    self.tail = Tail::Manifest;
                }
                Tail::Manifest => {
                    let z = self.zipper.take().ok_or_else(Self::finished)?;
                    blocking(move || z.zip.finish().map(drop).map_err(zip_error)).await??;
                    self.tail = Tail::Finished;
                }
                Tail::Finished => return Ok((self.sink.len() > 0).then(|| self.hand_on())),
            }
        }
    }

    /// Open the answer of the next entry's take and start its entry with its first piece,
    /// or mark the take skipped: a take whose answer fails before any of it is written (a
    /// glTF or C3D is built whole in its first piece) is skipped, not the export stopped.
    async fn open_next(&mut self) -> Result<()> {
        let entry = &self.entries[self.at];
        if entry.skipped.is_some() {
            self.at += 1;
            return Ok(());
        }
        let id = entry.id.clone();
        let request = RangeRequest {
            range: TimeRange::All,
            points: None,
            format: self.format,
            transform: self.transform,
            onto: self.onto.clone(),
            feet: self.feet,
        };
        let budget = self.budget.clone();
        let parent = &self.reservation;
        let opened = answer::open_waiting(
            &self.store,
            &self.caches,
            || budget.reservation_beside(parent),
            &self.limits,
            &id,
            request,
            BUDGET_WAIT,
        )
        .await;
        let first = match opened {
            Ok(a) => {
                // A take of many, read whole: past the chunk cache.
                let mut a = a.bulk();
                match a.next().await {
                    Ok(first) => Ok((a, first)),
                    Err(e) => Err(e),
                }
            }
            Err(e) => Err(e),
        };
        let (a, first) = match first {
            Ok(got) => got,
            Err(e) if e.is_the_takes_own() => {
                tracing::warn!(take = %id, error = %e, "a library export skips a take");
                self.entries[self.at].skipped = Some(reason(&e));
                self.at += 1;
                return Ok(());
            }
            Err(e) => return Err(e),
        };
        let e = &mut self.entries[self.at];
        e.frames = a.frames_out;
        e.fps = a.fps;
        e.metres_per_unit = a.metres_per_unit;
        e.points = points_written(std::mem::take(&mut e.points), a.points);
        let options = file_options(e.created_at, a.len_bound);
        let name = e.file.clone();
        self.answer = Some(a);
        self.input = first.map(|p| (p, 0));
        self.zip(move |z| z.start(&name, options)).await
    }

    /// Run `f` on the ZIP writer on the blocking pool (deflate is a pass over every byte).
    async fn zip(
        &mut self,
        f: impl FnOnce(&mut Zipper) -> Result<()> + Send + 'static,
    ) -> Result<()> {
        let mut z = self.zipper.take().ok_or_else(Self::finished)?;
        let (z, r) = blocking(move || {
            let r = f(&mut z);
            (z, r)
        })
        .await?;
        self.zipper = Some(z);
        r
    }

    fn finished() -> Error {
        Error::Internal("the export's ZIP was already finished".into())
    }

    fn hand_on(&self) -> Bytes {
        self.reservation.hand_on(self.sink.take())
    }
}

/// How an entry is stored: deflated, with its take's creation time (the same bytes for the
/// same selection), readable by anyone, and ZIP64 where it may pass 4 GiB.
fn file_options(created_ms: i64, len_bound: u64) -> SimpleFileOptions {
    let (y, mo, d, h, mi, s) = crate::dates::utc_fields(created_ms);
    // ZIP times run from 1980 to 2107; outside them, the format's own default (1980).
    let time = u16::try_from(y)
        .ok()
        .and_then(|y| {
            zip::DateTime::from_date_and_time(y, mo as u8, d as u8, h as u8, mi as u8, s as u8).ok()
        })
        .unwrap_or_default();
    SimpleFileOptions::default()
        .compression_method(METHOD)
        .last_modified_time(time)
        .unix_permissions(0o644)
        .system(zip::System::Unix)
        .large_file(len_bound >= u64::from(u32::MAX) - (1 << 20))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_files_points_are_the_takes_and_what_the_transforms_add() {
        let take = || vec!["a".to_string(), "b".to_string()];
        assert_eq!(points_written(take(), Some(2)), ["a", "b"]);
        assert_eq!(
            points_written(take(), Some(4)),
            ["a", "b", "root_motion", "root_motion_forward"]
        );
        assert_eq!(points_written(take(), Some(3)), ["a", "b", "root_motion"]);
        assert!(
            points_written(take(), None).is_empty(),
            "BVH names its joints"
        );
    }

    #[test]
    fn names_are_safe_and_unique_ignoring_case() {
        let mut n = Names::default();
        assert_eq!(n.file("CMU", "01_01", "glb"), "CMU/01_01.glb");
        assert_eq!(n.file("CMU", "01_01", "glb"), "CMU/01_01_2.glb");
        assert_eq!(n.file("cmu", "01_01", "glb"), "cmu/01_01_3.glb");
        // A take named like a suffixed one is moved on, not overwritten.
        assert_eq!(n.file("CMU", "01_01_2", "glb"), "CMU/01_01_2_2.glb");
        assert_eq!(n.file("", "a/b\\c:d", "bvh"), "_/a_b_c_d.bvh");
        assert_eq!(n.file("lab", "歩く", "c3d"), "lab/歩く.c3d");
        assert_eq!(n.file("lab", "..", "c3d"), "lab/_...c3d");
        assert_eq!(n.file("lab", "con", "c3d"), "lab/_con.c3d");
        assert_eq!(n.file("lab", "COM1.take", "c3d"), "lab/_COM1.take.c3d");
        assert_eq!(n.file("lab", "", "c3d"), "lab/_.c3d");
    }

    #[test]
    fn manifest_lines_quote_what_csv_must() {
        assert_eq!(csv_field("plain"), "plain");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(csv_field("two\nlines"), "\"two\nlines\"");
        assert_eq!(manifest_head().trim_end().split(',').count(), COLUMNS.len());
    }

    /// Text a spreadsheet would run is made inert; plain text and numbers are as they were.
    #[test]
    fn manifest_text_never_runs_as_a_formula() {
        assert_eq!(csv_text("=cmd|'/C calc'!A0"), "\"'=cmd|'/C calc'!A0\"");
        for danger in ["+1+1", "-2+3", "@SUM(A1)", "\tx", "\rx", "=\"q\""] {
            let cell = csv_text(danger);
            assert!(cell.starts_with("\"'"), "{danger:?} → {cell}");
        }
        assert_eq!(csv_text("=\"q\""), "\"'=\"\"q\"\"\"");
        assert_eq!(csv_text("walk_01"), "walk_01");
        assert_eq!(csv_text("a,b"), "\"a,b\"");
        assert_eq!(csv_text(""), "");
    }
}
