//! mocapstore archives motion-capture libraries with error-bounded compression.
//!
//! # Layout
//!
//! Dependencies point one way, from the top of this list to the bottom:
//!
//! - [`cli`]: the `mocapstore` command line (`serve`, `inspect`, `convert`, `bench`); the only
//!   place that touches files and the terminal.
//! - [`http`]: the axum API under `/v1`, errors as JSON, metrics; no math, no SQL.
//! - [`service`]: use-cases (ingest with per-take codec choice, range fetch); moves codec work
//!   to the blocking pool.
//! - [`store`]: SQLite (default) and Postgres via sqlx; takes are written in one transaction.
//! - [`codec`]: codecs (`raw`, `quant`, `mdtt`), the chunked container, the entropy stage
//!   and rate control to an error bound. Pure, like `motion`.
//! - [`motion`]: the `Motion` model (positions, units, gaps, skeletons), forward kinematics,
//!   error metrics and the file formats in [`motion::formats`] (BVH, C3D, TRC, JSON, NPY in;
//!   BVH, TRC, JSON, NPY, CSV, raw f32 out). Pure: no I/O, no async, no database.
//!
//! Beside them, [`limits`] holds every bound on untrusted input and server memory (one
//! place, read by every layer), and [`corpus`] says where the real-data corpus and its
//! manifest are (tests and benchmarks).

pub mod cli;
pub mod codec;
pub mod corpus;
#[doc(hidden)]
pub mod fuzzing;
pub mod http;
pub mod limits;
pub mod motion;
pub mod service;
pub mod store;
