//! mocapstore archives motion-capture libraries with error-bounded compression.
//!
//! # Layout
//!
//! Dependencies point one way, from the top of this list to the bottom:
//!
//! - [`cli`]: the `mocapstore` command line (`inspect`, `convert`, `bench`; later `serve`,
//!   `ingest`); the only place that touches files and the terminal.
//! - [`codec`]: codecs (`raw`, `quant`, `mdtt`), the chunked container, the entropy stage
//!   and rate control to an error bound. Pure, like `motion`.
//! - [`motion`]: the `Motion` model (positions, units, gaps, skeletons), forward kinematics,
//!   error metrics and the file formats in [`motion::formats`] (BVH, C3D, TRC, JSON, NPY in;
//!   BVH, TRC, JSON, NPY, CSV, raw f32 out). Pure: no I/O, no async, no database.
//!
//! - [`corpus`]: where the real-data corpus is, and its manifest (tests and benchmarks).
//!
//! Still to come (see `../shared/DESIGN.md`): `store/` (SQLite and Postgres via sqlx),
//! `service/` (use-cases) and `http/` (axum).

pub mod cli;
pub mod codec;
pub mod corpus;
pub mod http;
pub mod motion;
pub mod service;
pub mod store;
