//! The service's integration tests (store, HTTP API, streams, bases, CLI), as modules of one
//! test binary: each integration test file is a crate of its own that links the server, the
//! HTTP client and both database drivers again, and eight of them made up most of a clean
//! build. Every test opens its own store (see `common`), so they also run in parallel here.

mod common;

#[path = "../bodies/manifest.rs"]
mod manifest;

mod access;
mod archive;
mod bases;
mod bodies;
mod c3d;
mod choice;
mod cli;
mod cluster;
mod export;
mod fbx;
mod gltf_in;
mod hostile;
mod http;
mod library;
mod limits;
mod motion_stats;
mod openapi;
mod python;
mod ranges;
mod retarget;
mod robustness;
mod search;
mod skeletons;
mod store;
mod streams;
mod transforms;
mod viewer;
