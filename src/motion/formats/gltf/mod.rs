//! glTF 2.0: takes read from a `.glb` or `.gltf` ([`read`]) and written as one
//! ([`write`]).

pub(crate) mod read;
mod write;

pub use write::*;
