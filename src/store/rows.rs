//! Row types and the mapping between them and SQL, shared by both backends.

use sqlx::Row;

use super::{Error, Result};

/// One stored chunk.
#[derive(Debug, Clone, PartialEq)]
pub struct ChunkRow {
    pub idx: i64,
    pub first_frame: i64,
    pub frames: i64,
    pub crc32c: u32,
    pub payload: Vec<u8>,
}

/// A take's codec, stored bytes and frames as stored ([`super::Store::coding_stamp`]).
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct StampRow {
    pub codec: String,
    pub stored_bytes: i64,
    pub frames: i64,
    pub body_rev: i64,
}

/// Where a chunk sits and how to check it, without its payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChunkEntry {
    pub idx: i64,
    pub first_frame: i64,
    pub frames: i64,
    pub crc32c: u32,
    /// Payload bytes.
    pub len: i64,
}

/// A take's row as stored: every column, and its tags. The store keeps rows and does not
/// read them; the service parses one into its domain record (`service::take::Take`).
#[derive(Debug, Clone, PartialEq)]
pub struct TakeRow {
    pub id: String,
    pub name: String,
    pub library: String,
    pub tags: Vec<String>,
    /// Its labels, by key.
    pub labels: Vec<LabelRow>,
    pub fps: f64,
    /// Frames, sizes and errors: what a live take's commits update.
    pub totals: TakeTotals,
    pub points: i64,
    pub metres_per_unit: f64,
    pub layout: String,
    pub source_format: String,
    pub codec: String,
    pub max_bound_mm: f64,
    /// `None` when no mean bound was asked for.
    pub mean_bound_mm: Option<f64>,
    /// The codec container header (chunk index included).
    pub header: Vec<u8>,
    /// Point names, unit provenance, codec decision, axes, warnings: JSON text, packed
    /// ([`super::packed`]).
    pub meta: Vec<u8>,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// While a live stream codes the take: when its lease runs out (ms since the epoch).
    pub live_until: Option<i64>,
    /// The stored skeleton of a skeleton take (its id).
    pub skeleton_id: Option<String>,
    /// How many times its body (in `meta`) changed after it was stored.
    pub body_rev: i64,
}

/// One label of a take (`take_labels`): `value` is its canonical text
/// ([`crate::labels::Label::canonical`]), what filters compare; `number` whether it was
/// given as a number.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelRow {
    pub key: String,
    pub value: String,
    pub number: bool,
}

/// Numeric columns of a take's row (8 bytes each on disk).
const NUMERIC_COLUMNS: i64 = 21;
/// A chunk row beside its payload: its key (the take's and its index, migration 0020) and
/// three integers.
const CHUNK_ROW: i64 = 4 * 8;
/// A tag's or label's row beside its text: the take's key.
const KEY: usize = 8;

/// What a take costs on disk, beside the database's own page and index overhead: its
/// container (header and chunk payloads, `stored_bytes`), its row's text columns
/// (`text_bytes`: the packed record, names, ids) and numbers, and its chunk rows' keys. A
/// skeleton or basis it shares with other takes is stored once and not counted here.
pub fn disk_bytes(stored_bytes: i64, text_bytes: i64, chunk_rows: i64) -> i64 {
    stored_bytes + text_bytes + NUMERIC_COLUMNS * 8 + chunk_rows * CHUNK_ROW
}

impl TakeRow {
    /// Bytes of the row's text columns (and tags and labels).
    pub fn text_bytes(&self) -> i64 {
        let tags: usize = self.tags.iter().map(|t| t.len() + KEY).sum::<usize>()
            + self
                .labels
                .iter()
                .map(|l| l.key.len() + l.value.len() + KEY)
                .sum::<usize>();
        (self.id.len()
            + self.name.len()
            + self.library.len()
            + self.layout.len()
            + self.source_format.len()
            + self.codec.len()
            + self.meta.len()
            + self.skeleton_id.as_ref().map_or(0, String::len)
            + tags) as i64
    }
}

/// The columns a live take's commits update: its running totals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TakeTotals {
    pub frames: i64,
    pub duration_s: f64,
    pub raw_bytes: i64,
    pub stored_bytes: i64,
    pub ratio: f64,
    pub mean_mm: f64,
    pub rms_mm: f64,
    pub max_mm: f64,
    pub kg_percent: f64,
}

/// A take to insert: its row and its chunks.
#[derive(Debug, Clone)]
pub struct NewTake {
    pub row: TakeRow,
    pub chunks: Vec<ChunkRow>,
    /// The shared basis the take was coded with (its id), if any: the take then holds a
    /// reference that keeps the basis from being deleted.
    pub basis: Option<String>,
    /// The skeleton `row.skeleton_id` names, stored with the take unless it is already.
    pub skeleton: Option<super::SkeletonRow>,
    /// The take's error over time (`motion::metrics::ErrorSeries` bytes), if measured.
    pub errors: Option<Vec<u8>>,
    /// Its analog channels, if it has any.
    pub analog: Option<AnalogRows>,
    /// The uploaded file's parameters, if its format has any.
    pub parameters: Option<ParametersRow>,
    /// Its model outputs (`codec::outputs` bytes), if the file had any.
    pub outputs: Option<Vec<u8>>,
    /// For a live stream's take: the server that codes it, and its coder's state.
    pub stream: Option<super::NewStream>,
}

/// A take's analog channels as stored: their container header, its sizes, its chunks.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalogRows {
    pub header: Vec<u8>,
    pub raw_bytes: i64,
    pub stored_bytes: i64,
    pub chunks: Vec<ChunkRow>,
}

/// The parameters an uploaded file carried, in a stated `format`.
#[derive(Debug, Clone, PartialEq)]
pub struct ParametersRow {
    pub format: String,
    pub payload: Vec<u8>,
}

impl std::ops::Deref for NewTake {
    type Target = TakeRow;
    fn deref(&self) -> &TakeRow {
        &self.row
    }
}

pub const TAKE_COLUMNS: &str = "id, name, library, fps, frames, points, duration_s, \
    metres_per_unit, layout, source_format, codec, max_bound_mm, mean_bound_mm, raw_bytes, \
    stored_bytes, ratio, mean_mm, rms_mm, max_mm, kg_percent, header, meta, created_at, live_until, skeleton_id, body_rev";

/// The running totals' columns as `$1..$9`, in the order [`bind_totals`] binds them: every
/// statement that writes them starts with them.
pub const SET_TOTALS: &str = "frames = $1, duration_s = $2, raw_bytes = $3, stored_bytes = $4, \
    ratio = $5, mean_mm = $6, rms_mm = $7, max_mm = $8, kg_percent = $9";

/// Insert a take's row, answering its key (`takes.key`, which the database gives).
pub const INSERT_TAKE: &str = "INSERT INTO takes (frames, duration_s, raw_bytes, \
    stored_bytes, ratio, mean_mm, rms_mm, max_mm, kg_percent, id, name, library, fps, points, \
    metres_per_unit, layout, source_format, codec, max_bound_mm, mean_bound_mm, header, meta, \
    created_at, live_until, skeleton_id, errors) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, \
    $10, $11, $12, $13, $14, $15, $16, $17, $18, $19, $20, $21, $22, $23, $24, $25, $26) \
    RETURNING key";

/// Bind a take's running totals, in [`SET_TOTALS`] order, to a query of either backend.
pub fn bind_totals<'q, DB: sqlx::Database>(
    q: sqlx::query::Query<'q, DB, <DB as sqlx::Database>::Arguments<'q>>,
    t: &TakeTotals,
) -> sqlx::query::Query<'q, DB, <DB as sqlx::Database>::Arguments<'q>>
where
    f64: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    i64: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
{
    q.bind(t.frames)
        .bind(t.duration_s)
        .bind(t.raw_bytes)
        .bind(t.stored_bytes)
        .bind(t.ratio)
        .bind(t.mean_mm)
        .bind(t.rms_mm)
        .bind(t.max_mm)
        .bind(t.kg_percent)
}

/// Bind a take's columns, in [`INSERT_TAKE`] order, to a query of either backend: all but
/// the last, `errors`, which is [`NewTake::errors`].
pub fn bind_take<'q, DB: sqlx::Database>(
    q: sqlx::query::Query<'q, DB, <DB as sqlx::Database>::Arguments<'q>>,
    s: &'q TakeRow,
) -> sqlx::query::Query<'q, DB, <DB as sqlx::Database>::Arguments<'q>>
where
    String: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    f64: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    i64: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    Option<i64>: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    Option<f64>: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    Option<String>: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    Vec<u8>: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
{
    bind_totals(q, &s.totals)
        .bind(s.id.clone())
        .bind(s.name.clone())
        .bind(s.library.clone())
        .bind(s.fps)
        .bind(s.points)
        .bind(s.metres_per_unit)
        .bind(s.layout.clone())
        .bind(s.source_format.clone())
        .bind(s.codec.clone())
        .bind(s.max_bound_mm)
        .bind(s.mean_bound_mm)
        .bind(s.header.clone())
        .bind(s.meta.clone())
        .bind(s.created_at)
        .bind(s.live_until)
        .bind(s.skeleton_id.clone())
}

/// Read a [`TakeRow`] (tags left empty) from either backend's row.
pub fn take_from_row<R: Row>(r: &R) -> Result<TakeRow>
where
    for<'a> &'a str: sqlx::ColumnIndex<R>,
    for<'a> String: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> f64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> i64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Option<i64>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Option<f64>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Option<String>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Vec<u8>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
{
    Ok(TakeRow {
        id: r.try_get("id")?,
        name: r.try_get("name")?,
        library: r.try_get("library")?,
        tags: Vec::new(),
        labels: Vec::new(),
        fps: r.try_get("fps")?,
        totals: TakeTotals {
            frames: r.try_get("frames")?,
            duration_s: r.try_get("duration_s")?,
            raw_bytes: r.try_get("raw_bytes")?,
            stored_bytes: r.try_get("stored_bytes")?,
            ratio: r.try_get("ratio")?,
            mean_mm: r.try_get("mean_mm")?,
            rms_mm: r.try_get("rms_mm")?,
            max_mm: r.try_get("max_mm")?,
            kg_percent: r.try_get("kg_percent")?,
        },
        points: r.try_get("points")?,
        metres_per_unit: r.try_get("metres_per_unit")?,
        layout: r.try_get("layout")?,
        source_format: r.try_get("source_format")?,
        codec: r.try_get("codec")?,
        max_bound_mm: r.try_get("max_bound_mm")?,
        mean_bound_mm: r.try_get("mean_bound_mm")?,
        header: r.try_get("header")?,
        meta: r.try_get("meta")?,
        created_at: r.try_get("created_at")?,
        live_until: r.try_get("live_until")?,
        skeleton_id: r.try_get("skeleton_id")?,
        body_rev: r.try_get("body_rev")?,
    })
}

/// Read a chunk and check its payload against the stored CRC-32C.
pub fn chunk_from_row<R: Row>(r: &R) -> Result<ChunkRow>
where
    for<'a> &'a str: sqlx::ColumnIndex<R>,
    for<'a> i64: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
    for<'a> Vec<u8>: sqlx::Decode<'a, R::Database> + sqlx::Type<R::Database>,
{
    let crc: i64 = r.try_get("crc32c")?;
    let c = ChunkRow {
        idx: r.try_get("idx")?,
        first_frame: r.try_get("first_frame")?,
        frames: r.try_get("frames")?,
        crc32c: u32::try_from(crc).map_err(|_| Error::Corrupt(format!("crc {crc}")))?,
        payload: r.try_get("payload")?,
    };
    if crc32c::crc32c(&c.payload) != c.crc32c {
        return Err(Error::Corrupt(format!(
            "chunk {} fails its checksum",
            c.idx
        )));
    }
    Ok(c)
}
