//! The names of the file formats: what a request or a file extension says, and what a
//! parse error names (apart from the readers and writers in [`super::formats`], so the
//! error type does not depend on them).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// A format name we do not know.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown format {0:?} (bvh, c3d, trc, json, npy, fbx, csv, f32, glb, gltf)")]
pub struct UnknownFormat(pub String);

/// A file format we read and/or write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Bvh,
    C3d,
    Trc,
    Json,
    Npy,
    /// Autodesk FBX (binary or ASCII).
    Fbx,
    Csv,
    /// Bare little-endian f32, `frames × points × 3`; write only (it has no header).
    F32,
    /// Binary glTF 2.0.
    Glb,
    /// glTF 2.0 as JSON, its buffers embedded.
    Gltf,
}

impl Format {
    pub fn name(self) -> &'static str {
        match self {
            Format::Bvh => "bvh",
            Format::C3d => "c3d",
            Format::Trc => "trc",
            Format::Json => "json",
            Format::Npy => "npy",
            Format::Fbx => "fbx",
            Format::Csv => "csv",
            Format::F32 => "f32",
            Format::Glb => "glb",
            Format::Gltf => "gltf",
        }
    }

    /// From a file name's extension (for writing; reading detects from content).
    pub fn from_extension(path: &str) -> Option<Format> {
        let ext = path.rsplit_once('.')?.1;
        ext.parse().ok()
    }

    pub fn can_read(self) -> bool {
        !matches!(self, Format::Csv | Format::F32)
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name().to_ascii_uppercase())
    }
}

impl FromStr for Format {
    type Err = UnknownFormat;
    fn from_str(s: &str) -> Result<Self, UnknownFormat> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "bvh" => Format::Bvh,
            "c3d" => Format::C3d,
            "trc" => Format::Trc,
            "json" => Format::Json,
            "npy" => Format::Npy,
            "fbx" => Format::Fbx,
            "csv" => Format::Csv,
            "f32" | "bin" | "raw" => Format::F32,
            "glb" => Format::Glb,
            "gltf" => Format::Gltf,
            other => return Err(UnknownFormat(other.to_string())),
        })
    }
}
