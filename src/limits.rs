//! Every bound the service puts on what a client may send it or make it hold, in one place.
//!
//! A store's worst bug is a crash, and the cheapest way to crash a server is to make it
//! allocate what a request only claims: a header's frame count, a stream's point count, a
//! `Content-Length`. So every size a client declares is checked here before it is used, and
//! memory is bounded per server, not only per request. The numbers are generous for real
//! capture (the largest marker sets are a few hundred points; a four-hour session at 240 fps
//! is 3.5 M frames) and small enough that no request can make the server hold gigabytes.
//!
//! [`Limits`] holds the tunable ones (`mocapstore serve --help` names their flags); the
//! constants below are physical facts, not tuning. The layers take the parts they need:
//! readers [`crate::motion::formats::ReadLimits`] and decoders
//! [`crate::codec::DecodeLimits`] (each `From<&Limits>`), streams and uploads the fields.
//! README ("Limits") and `openapi.yaml` quote the defaults; keep the three in step.

use std::ops::RangeInclusive;
use std::time::Duration;

/// Metres per stored unit that a take may declare or a client may state: from a micrometre
/// to a kilometre. Beyond either end the unit is a mistake (or an attack): errors in
/// millimetres would overflow or vanish.
pub const UNIT_METRES: RangeInclusive<f64> = 1e-6..=1e3;

/// Labels a take may carry ([`crate::labels`]): a dataset's sidecar has a handful; a
/// hundred would be a document, which belongs in a file beside the take, not in its record.
pub const MAX_LABELS: usize = 64;
/// Characters of a label's key (`content`, `subject.id`).
pub const MAX_LABEL_KEY_CHARS: usize = 64;
/// Characters of a label's text value.
pub const MAX_LABEL_VALUE_CHARS: usize = 256;

/// The most memory the FBX reader's library may allocate for one file (its node tree and
/// curves; geometry is never loaded), and again for each frame it evaluates: a hostile file
/// that claims more is refused, not allocated.
pub const MAX_FBX_MEMORY: usize = 1 << 30;

/// The largest character file a rig upload keeps (`POST /v1/skeletons`). Every glTF answer
/// on the rig is that file again with the take in it, built in memory under the answer
/// limit (four times the file, at most); a game character with its textures is a few MB.
pub const MAX_CHARACTER_BYTES: u64 = 32 << 20;

/// The largest JSON chunk of a character file: it is parsed as a document on every glTF
/// answer on the rig, which takes some twenty times its size.
pub const MAX_CHARACTER_JSON_BYTES: usize = 4 << 20;

/// The largest coordinate magnitude, in metres, that motion capture can mean: 10 km. A
/// value beyond it is not a position but a corrupt or hostile number, and refused.
pub const MAX_COORDINATE_M: f64 = 1e4;

/// The loosest error bound a client may state, mm (a kilometre): past any capture volume a
/// bound means nothing, and a codec's step derived from 1e308 mm is not a number.
pub const MAX_BOUND_MM: f64 = 1e6;

/// Frame rates a take or stream may have, frames per second.
pub const MAX_FPS: f64 = 100_000.0;

/// The frame rate a take or stream states, if it is one ([`MAX_FPS`]): the one check that
/// ingest's `fps=`, a stream's `fps`, and every parsed take apply.
pub fn fps(fps: f64) -> Result<f64, String> {
    if fps.is_finite() && fps > 0.0 && fps <= MAX_FPS {
        Ok(fps)
    } else {
        Err(format!("fps must be in (0, {MAX_FPS}], got {fps}"))
    }
}

/// Frame rates a take may be resampled to (`fps=` on a read or an export): below one frame
/// in 100 s a take is a handful of stills; above 10,000 fps no capture system records.
pub const RESAMPLE_FPS: RangeInclusive<f64> = 0.01..=10_000.0;

/// A rate a take may be resampled to ([`RESAMPLE_FPS`]).
pub fn resample_fps(fps: f64) -> Result<f64, String> {
    if fps.is_finite() && RESAMPLE_FPS.contains(&fps) {
        Ok(fps)
    } else {
        let (lo, hi) = (RESAMPLE_FPS.start(), RESAMPLE_FPS.end());
        Err(format!("fps must be between {lo} and {hi}, got {fps}"))
    }
}

/// The longest chunk a live stream may ask to be committed in, seconds: a watcher or a range
/// read of a live take waits at most this long for frames, and the pending chunk is held
/// in memory ([`Limits::stream_chunk_samples`] bounds its size too).
pub const MAX_CHUNK_SECONDS: f64 = 60.0;

/// A stream's `chunk_seconds`, if it is one: in (0, [`MAX_CHUNK_SECONDS`]].
pub fn chunk_seconds(s: f64) -> Result<f64, String> {
    if s.is_finite() && s > 0.0 && s <= MAX_CHUNK_SECONDS {
        Ok(s)
    } else {
        Err(format!(
            "chunk_seconds must be in (0, {MAX_CHUNK_SECONDS}], got {s}"
        ))
    }
}

/// Points of a take that per-take `mdtt` and shared `mdtt-set` bases code: their bases are
/// `3J × 3J` and found by an eigendecomposition of that size (cubic time, 72 MB of
/// covariance at this bound). Past it those codecs sit out (and say why); the others code.
pub const MDTT_MAX_POINTS: usize = 400;

/// Points of a take that `spca` codes: each segment's model is a `3J × 3J`
/// eigendecomposition, and segmentation fits one every few frames.
pub const SPCA_MAX_POINTS: usize = 400;

/// Points of a layout that an LSDT basis (`J × J` per coordinate) is trained or built for,
/// streams included: 3 × 2000² f32 is 48 MB per basis.
pub const LSDT_MAX_POINTS: usize = 2_000;

/// Seconds a client is told to wait (`Retry-After`) when the server is at its memory budget.
pub const RETRY_AFTER_S: u64 = 2;

/// How long a server trusts what the store said about a token (and whether any token
/// exists): a token revoked through another server sharing the database, or by the CLI,
/// stops working within this time. Short, since one lookup costs only tens of microseconds.
pub const TOKEN_CACHE: std::time::Duration = std::time::Duration::from_secs(2);

/// Token lookups cached at once; past it the cache is emptied, so made-up secrets cannot
/// grow it.
pub const TOKEN_CACHE_ENTRIES: usize = 10_000;

/// Libraries one token may be limited to.
pub const MAX_TOKEN_LIBRARIES: usize = 100;

/// Audit entries one request may ask for.
pub const MAX_AUDIT_PAGE: usize = 1_000;

/// Takes one listing page may ask for (`limit=`); also the page an export or a training
/// selection reads the library by.
pub const MAX_TAKES_PAGE: usize = 500;

/// Takes one `POST /v1/motion-stats` may name by id (`ids`): the takes of a training split.
pub const MAX_STATS_IDS: usize = 20_000;

/// Point layouts (a set of point names in one unit) one motion-statistics answer may hold:
/// what it holds grows with each. A selection of more is refused with what to do (narrow
/// it, select `points`, or ask `by=roles`).
pub const MAX_STATS_GROUPS: usize = 64;

/// Points in all the layouts of one motion-statistics answer: what it holds and writes
/// (about 450 bytes a point) grows with them.
pub const MAX_STATS_POINTS: usize = 20_000;

/// Takes a motion-statistics answer lists as skipped, each with its reason (it counts the
/// rest).
pub const MAX_STATS_SKIPPED: usize = 100;

/// Bytes of per-take motion statistics a server keeps ([`crate::service::motion_stats`]):
/// about 150 bytes a point, so 32 MiB keeps a few thousand takes of a full marker set.
pub const MOTION_STATS_CACHE_BYTES: usize = 32 << 20;

/// Bytes of takes' motion features a server keeps decoded for search
/// ([`crate::service::motion_index`]): about 700 bytes a second of motion, so 128 MiB
/// holds 50 hours.
pub const MOTION_INDEX_CACHE_BYTES: usize = 128 << 20;

/// Results one search answers at most (`k`), and from one take (`per_take`).
pub const MAX_SEARCH_K: usize = 100;
pub const MAX_SEARCH_PER_TAKE: usize = 10;
/// The longest query a search compares, in seconds (its windows against every take's):
/// a longer range is refused, naming t0/t1.
pub const MAX_SEARCH_QUERY_S: f64 = 120.0;

/// Windows from which search goes approximate by itself (`index=auto`): past them, the
/// takes a search may see are proposed by the graph of every full-body take's windows
/// ([`crate::motion::nearest`]) and only those are scored. Below, exact search answers
/// well within 50 ms (p50 18.7 ms at 19,490 windows on 2 cores; 96 ms at 93,552).
pub const APPROXIMATE_FROM_WINDOWS: usize = 40_000;
/// Windows the graph holds at most (about 2 KB each: 1 GB at this cap, 70 hours of
/// motion; twice that while a new graph is built beside the one searched); the takes past
/// it, in the order they were stored, are not read for it and are scored exactly.
pub const APPROXIMATE_MAX_WINDOWS: usize = 500_000;
/// The graph is built again, in the background, once takes it does not hold (stored or
/// changed since) have this share of its windows: they are scored exactly meanwhile.
pub const APPROXIMATE_REBUILD_SHARE: f64 = 0.1;
/// … and once it is this old (seconds) when a search uses it, so that the windows of takes
/// deleted or changed since (walked past, never answered) do not pile up.
pub const APPROXIMATE_REBUILD_AFTER_S: u64 = 3_600;
/// A build that failed is not tried again for this long (seconds).
pub const APPROXIMATE_RETRY_AFTER_S: u64 = 60;
/// Deepest a search looks in the graph: its beam at most (the crate walks on while a
/// filter leaves its beam unfilled); past it, the takes not proposed are scored exactly.
pub const APPROXIMATE_MAX_BEAM: usize = 4_096;

/// Jobs one listing answers at most.
pub const MAX_JOBS_LISTED: usize = 1_000;

/// The longest a client may ask a job's answer to wait for it to finish (`wait_s=`),
/// seconds.
pub const MAX_JOB_WAIT_S: u64 = 600;

/// Ranges one `GET /v1/ranges` may ask for: a training batch. Each part is checked before
/// the first is written and opened again when its turn comes, so a batch of more takes than
/// the server keeps decoders for ([`crate::service::prepared::DECODERS`]) would build each
/// decoder twice and push other callers' out. Each part is opened, decoded and written in
/// turn, so what a batch holds does not grow with it.
pub const MAX_RANGES: usize = 256;

/// Coded chunks one live stream holds while its database is away (they are stored when it
/// is back): past it, appends are refused (503) until they are. Coded, a minute of 100
/// points at 120 fps is well under 1 MB.
pub const STREAM_UNSAVED_BYTES: usize = 64 << 20;

/// Watchers of one live stream at once (the viewer's live page, `GET /v1/streams/{id}/events`).
pub const STREAM_WATCHERS: usize = 16;

/// Batches of frames queued for a watcher that reads slower than frames arrive; past it the
/// watcher skips to the newest (and is told how many it missed).
pub const STREAM_WATCH_QUEUE: usize = 16;

/// Samples (frames × points) of one append passed on to watchers: the newest frames of a
/// larger batch. With [`STREAM_WATCH_QUEUE`] this bounds what a stream's watchers hold,
/// ≤ 16 × 50,000 × 12 bytes ≈ 9.6 MB, shared by all of them.
pub const STREAM_WATCH_SAMPLES: usize = 50_000;

/// Bytes of an audit entry's free-text fields (the path asked for, the detail) kept; longer
/// ones are cut and say so. A 65,000-character path is not evidence worth 65 KB a row.
pub const AUDIT_FIELD_BYTES: usize = 256;

/// Callers (addresses or tokens) whose refused requests are counted apart within one
/// minute; past it the rest of the minute's refusals are counted together, so a flood from
/// many addresses adds one row more, not one per address.
pub const AUDIT_REFUSED_KEYS: usize = 1_000;

/// How often a token's `last_used_at` is written: at most once this often per token, so
/// that reads do not each cost a database write.
pub const TOKEN_LAST_USED_EVERY: Duration = Duration::from_secs(60);

/// Latest capture time an append may carry (`captured_ms`, ms since the Unix epoch): the
/// year 3000. Earlier than the epoch is refused too.
pub const MAX_CAPTURE_MS: i64 = 32_503_680_000_000;

/// The longest take record (its meta JSON) the store packs or unpacks
/// (`store::packed`): far above any record the service writes (point names, events and
/// model outputs are bounded by the readers' limits), so that a corrupt stored frame cannot
/// ask for unbounded memory.
pub const MAX_RECORD_BYTES: usize = 64 << 20;

/// The tunable limits, with their defaults in [`Limits::default`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest request body, bytes. A larger `Content-Length` is refused (413) before any
    /// of the body is read; a body without one is cut off at this size.
    pub upload_bytes: u64,
    /// Largest body of a frames append to a live stream, bytes.
    pub append_bytes: u64,
    /// Largest JSON request body of the other routes (open a stream, train, edit), bytes.
    pub json_body_bytes: u64,
    /// Request bodies held at once across the whole server, bytes, counted as they arrive
    /// (not as declared). A request that would go over waits for nothing: it gets 503
    /// with `Retry-After`.
    pub inflight_bytes: u64,
    /// Points (markers, joints and end sites) in one take.
    pub points: u64,
    /// Frames in one take.
    pub frames: u64,
    /// Frames × points of one take: what memory really scales with.
    pub samples: u64,
    /// Nesting depth of a BVH hierarchy (root = 1). Parsers never recurse on it; the bound
    /// only keeps absurd files out.
    pub hierarchy_depth: u64,
    /// Analog values (rows × channels) of one take. Held as 4-byte integers or floats while
    /// a take is read and coded, so the default bounds that to 400 MB; a 512 MiB upload of
    /// 16-bit values could declare 268 M.
    pub analog_samples: u64,
    /// Points in one live stream. A stream holds a spatial basis of 3 × points² values and
    /// an encoder state, so this bounds the memory of each open stream.
    pub stream_points: u64,
    /// Streams open at once on this server.
    pub open_streams: u64,
    /// Frames × points in one stream chunk (what a stream keeps pending before it codes).
    pub stream_chunk_samples: u64,
    /// Bytes of frames a stream keeps for re-encoding on finish; past it the stream drops
    /// the copy (and says so) rather than grow without bound.
    pub stream_archive_bytes: u64,
    /// Requests per second each token may make (each address, for requests without one
    /// on a server that needs tokens), sustained; 0: no limit. Past it: 429 with
    /// `Retry-After`. Anonymous requests on a server without tokens (loopback only) are
    /// not limited.
    pub requests_per_s: u64,
    /// Requests a token (or address) may make at once above the sustained rate.
    pub request_burst: u64,
    /// Of [`Limits::inflight_bytes`], what one caller (a token, or an address without one)
    /// may hold across its uploads at once: others keep the rest. Alone, a caller may
    /// still send one body of the route's full size.
    pub body_share_bytes: u64,
    /// A request body from which nothing arrives for this long is dropped (408), and
    /// what it held is freed.
    pub body_idle: Duration,
    /// The largest range answer, frames × points (checked before anything is decoded).
    pub answer_samples: u64,
    /// Memory range answers hold at once across the server, bytes: each reserves what it
    /// will hold (about one decoded chunk, the payloads read ahead and output not yet
    /// written; [`crate::service::answer`]), whatever the take's length; past it, 503.
    pub answer_bytes: u64,
    /// Of [`Limits::answer_bytes`], what one caller's answers may hold at once.
    pub answer_share_bytes: u64,
    /// Connections open at once; past it a new one is answered 503 and closed.
    pub connections: u64,
    /// Connections open at once from one address.
    pub connections_per_address: u64,
    /// Time a client has to send a request's headers, from its first byte.
    pub header_timeout: Duration,
    /// A connection with no request in progress is closed after this long.
    pub idle_timeout: Duration,
    /// A connection whose client reads nothing of an answer for this long is closed.
    pub send_timeout: Duration,
    /// Live streams one caller may have open at once (of [`Limits::open_streams`]).
    pub streams_per_caller: u64,
    /// Watchers one caller may have on one stream at once (of [`STREAM_WATCHERS`]).
    pub watchers_per_caller: u64,
    /// Audit entries older than this are deleted (by every server, once a maintenance
    /// period).
    pub audit_retention: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            upload_bytes: 512 << 20,
            append_bytes: 64 << 20,
            json_body_bytes: 1 << 20,
            inflight_bytes: 1 << 30,
            points: 10_000,
            frames: 20_000_000,
            samples: 200_000_000,
            hierarchy_depth: 512,
            analog_samples: 100_000_000,
            stream_points: 1_000,
            open_streams: 32,
            stream_chunk_samples: 2_000_000,
            stream_archive_bytes: 256 << 20,
            requests_per_s: 200,
            request_burst: 400,
            body_share_bytes: 512 << 20,
            body_idle: Duration::from_secs(20),
            answer_samples: 200_000_000,
            answer_bytes: 256 << 20,
            answer_share_bytes: 64 << 20,
            // With the database's connections, the log and the listener, well within the
            // 1,024 files a service is commonly allowed.
            connections: 768,
            connections_per_address: 256,
            header_timeout: Duration::from_secs(10),
            // Longer than the 60 s idle time of common load balancers, so that the balancer
            // closes a connection first and never sends on one this server is closing.
            idle_timeout: Duration::from_secs(75),
            send_timeout: Duration::from_secs(60),
            streams_per_caller: 8,
            watchers_per_caller: 4,
            audit_retention: Duration::from_secs(90 * 24 * 3600),
        }
    }
}

/// Check a declared amount against its limit: the reason, naming both, when over.
pub fn check(what: &str, actual: u64, limit: u64) -> Result<(), String> {
    if actual > limit {
        Err(format!("{what} is {actual}, over the limit of {limit}"))
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layers_get_the_same_numbers() {
        let l = Limits::default();
        let reader = crate::motion::formats::ReadLimits::from(&l);
        assert_eq!(reader.max_points, l.points);
        assert_eq!(crate::codec::DecodeLimits::from(&l).max_samples, l.samples);
        assert_eq!(crate::motion::formats::ReadLimits::default(), reader);
        assert!(check("points", 3, 2)
            .unwrap_err()
            .contains("over the limit of 2"));
        assert!(check("points", 2, 2).is_ok());
    }

    #[test]
    fn rates_and_chunk_lengths_are_checked_at_both_ends() {
        assert_eq!(fps(MAX_FPS), Ok(MAX_FPS));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, MAX_FPS * 1.01] {
            assert!(fps(bad).is_err(), "{bad}");
        }
        assert!(resample_fps(0.01).is_ok() && resample_fps(10_000.0).is_ok());
        assert!(resample_fps(0.009).is_err() && resample_fps(10_001.0).is_err());
        assert_eq!(chunk_seconds(MAX_CHUNK_SECONDS), Ok(60.0));
        assert!(chunk_seconds(0.0).is_err() && chunk_seconds(60.5).is_err());
    }
}
