//! glTF 2.0: takes read from a `.glb` or `.gltf` ([`read`]) and written as one
//! ([`write`]); a skinned character's bind pose read ([`read::bind_pose`]) and the
//! character written back playing a take ([`character`]).

pub mod character;
pub(crate) mod read;
mod write;

pub use write::*;
