//! mocapstore archives motion-capture libraries with error-bounded compression: it reads
//! takes (BVH, C3D, TRC, JSON, NPY, FBX), codes each with the smallest codec that meets the user's
//! error bound, stores independently decodable chunks in SQLite or Postgres, and serves any
//! frame range of any take.
//!
//! This library is the product's core; the `mocapstore` command line (`src/main.rs`, the
//! `cli` feature, on by default) is a binary on top of it: `serve`, `ingest`, `inspect`,
//! `convert`, `bench`, `streamtest`, `loadtest`, `train-bases`, `verify`, `export`,
//! `import`. Code that embeds the codecs or the store depends on this crate with
//! `default-features = false` and compiles no HTTP client, plots or argument parser.
//!
//! # Layout
//!
//! Dependencies point one way, from the top of this list to the bottom:
//!
//! - [`http`]: the axum API under `/v1` (`openapi.yaml`), errors as JSON, request bodies
//!   under the server's budget, metrics, bearer tokens, route scopes, CORS, rate limits and
//!   the audit of writes ([`http::auth`]), and the connections themselves: caps and
//!   timeouts ([`http::serve`]). Parses requests into typed values, calls the service,
//!   writes responses; no math, no SQL.
//! - [`service`]: use-cases — ingest with per-take codec choice, range answers written a
//!   chunk at a time ([`service::answer`]), live streams, library queries, shared-basis
//!   training, verify/export/import, tokens and the audit log ([`service::access`]), and
//!   the memory requests may hold ([`service::budget`]). Owns the
//!   typed take record ([`service::take::Take`]) and moves codec work to the blocking pool.
//! - [`store`]: SQLite (default) and Postgres via sqlx; keeps rows, in one transaction per
//!   change.
//! - [`codec`]: the codecs (`raw`, `quant`, `mdtt`, `mdtt-shared`, `lsdt-clip`,
//!   `lsdt-frame`, `spca`, `pga`, `bvh-lossless`, `rot`, and the analog channels'
//!   `analog-lossless` and `analog-bounded`), found by id in one registry ([`codec::codec`]);
//!   the chunked container; the one encode path ([`codec::encode`] and its
//!   [`codec::EncodeOptions`], [`codec::stream`] for live streams) and the one read path ([`codec::Reader`]); shared bases and
//!   skeletons; rate control to a bound. Pure.
//!
//! `docs/ARCHITECTURE.md` walks through these layers: an ingest and a range read end to
//! end, the words the code uses, and how to add a codec or a file format.
//! - [`motion`]: the `Motion` model (positions, units, gaps, skeletons), forward kinematics,
//!   error metrics and the file formats in [`motion::formats`] (BVH, C3D, TRC, JSON, NPY, FBX in;
//!   BVH, C3D, TRC, JSON, NPY, CSV, raw f32, glTF out) and the transforms between
//!   decoder and writer ([`motion::transform`]: resampling, root motion, axes, units). Pure: no I/O, no async, no database.
//!
//! Beside them, depending on nothing: [`limits`] holds every bound on untrusted input and
//! server memory (one place; each layer converts it to its own), [`labels`] a take's
//! key → value labels and how they are read (queries, sidecar files, name patterns), [`rng`] the deterministic
//! generator trainers and test motions draw from, [`dates`] the calendar of the Unix clock,
//! and [`corpus`] says where the real-data corpus and its manifest are (tests and benchmarks).

pub mod codec;
pub mod corpus;
pub mod dates;
#[doc(hidden)]
pub mod fuzzing;
pub mod http;
pub mod labels;
pub mod limits;
pub mod motion;
pub mod rng;
pub mod service;
pub mod store;
