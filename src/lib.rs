//! mocapstore archives motion-capture libraries with error-bounded compression.
//!
//! # Layout
//!
//! Dependencies point one way, from the top of this list to the bottom:
//!
//! - [`cli`]: the `mocapstore` command line (`inspect`, `convert`, later `serve`, `ingest`,
//!   `bench`); the only place that touches files and the terminal.
//! - [`motion`]: the `Motion` model (positions, units, gaps, skeletons), forward kinematics,
//!   error metrics and the file formats in [`motion::formats`] (BVH, C3D, TRC, JSON, NPY in;
//!   BVH, TRC, JSON, NPY, CSV, raw f32 out). Pure: no I/O, no async, no database.
//!
//! Still to come, in this order (see `../shared/DESIGN.md`): `codec/` (pure encoders and the
//! container format), `store/` (SQLite and Postgres via sqlx), `service/` (use-cases) and
//! `http/` (axum).

pub mod cli;
pub mod codec;
pub mod corpus;
pub mod motion;
