//! A rig uploaded on its own (`POST /v1/skeletons`): the skeleton of a character or rig
//! file and the pose it stands in when nothing moves it.
//!
//! - **glTF** (`.glb`, `.gltf` with its one buffer embedded): a skinned character at its
//!   bind pose ([`super::gltf::read::bind_pose`]: its nodes' resting transforms), metres and
//!   +Y up; the file is kept (at most [`crate::limits::MAX_CHARACTER_BYTES`], and only if it
//!   can be written back), so that motion on its skeleton comes back as the character
//!   playing it.
//! - **FBX**: the skinned bones at their bind pose ([`super::fbx::bind_pose`]), in the
//!   file's unit and axes.
//! - **BVH**: the hierarchy, standing as its offsets say (rotations zero).

use super::{Format, ReadLimits, ReadOptions};
use crate::motion::error::{Error, Result};
use crate::motion::skeleton::Joint;

/// The skeleton of a rig file.
#[derive(Debug, Clone)]
pub struct RigFile {
    pub format: Format,
    pub joints: Vec<Joint>,
    /// Channel values of the rest pose, where the rig does not stand in its offsets'.
    pub rest: Option<Vec<f64>>,
    /// Whether the file is a character to keep (a skinned glTF), written back with motion.
    pub character: bool,
    pub warnings: Vec<String>,
}

/// The rig of `bytes`, a file of `format` (by content when `None`).
pub fn read(bytes: &[u8], format: Option<Format>, limits: &ReadLimits) -> Result<RigFile> {
    limits.check_bytes(bytes.len())?;
    let format = match format {
        Some(f) => f,
        None => super::detect(bytes)?,
    };
    match format {
        Format::Glb | Format::Gltf => {
            let most = crate::limits::MAX_CHARACTER_BYTES;
            if bytes.len() as u64 > most {
                return Err(Error::Limit {
                    what: "character file bytes",
                    actual: bytes.len() as u64,
                    limit: most,
                });
            }
            let bind = super::gltf::read::bind_pose(bytes, limits)?;
            // Kept only if it can be written back: its bind pose as one frame.
            let rest = super::gltf::character::Motion {
                name: "bind pose",
                joints: &bind.skeleton.joints,
                values: &bind.skeleton.values,
                frames: 1,
                fps: 30.0,
                extras: serde_json::Value::Null,
            };
            super::gltf::character::animate(bytes, limits, &rest, true)?;
            Ok(RigFile {
                format,
                joints: bind.skeleton.joints,
                rest: Some(bind.skeleton.values),
                character: true,
                warnings: bind.warnings,
            })
        }
        Format::Fbx => {
            let (skeleton, warnings) = super::fbx::bind_pose(bytes, limits)?;
            Ok(RigFile {
                format,
                joints: skeleton.joints,
                rest: Some(skeleton.values),
                character: false,
                warnings,
            })
        }
        Format::Bvh => {
            let options = ReadOptions {
                limits: *limits,
                ..Default::default()
            };
            let loaded = super::read_as(Format::Bvh, bytes, &options)?;
            let skeleton = loaded
                .motion
                .skeleton
                .ok_or_else(|| Error::Invalid("the BVH file has no hierarchy".into()))?;
            Ok(RigFile {
                format,
                joints: skeleton.joints,
                rest: None,
                character: false,
                warnings: loaded.warnings,
            })
        }
        other => Err(Error::Invalid(format!(
            "a rig comes from a glTF or FBX character or a BVH hierarchy, not {}",
            other.name()
        ))),
    }
}
