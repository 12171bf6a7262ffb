//! Layout signatures: which takes share a skeleton or marker set.
//!
//! Learned bases (LSDT, MDTT database mode) only make sense across takes whose points mean
//! the same thing in the same order, so they are keyed by this signature. It hashes the
//! point names and, for skeleton takes, the topology and channel layout — but not the bone
//! offsets, which differ between performers of the same rig.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::skeleton::Animation;

/// 128 bits of BLAKE3 over a canonical description of the layout, shown as hex.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct LayoutSignature(pub [u8; 16]);

impl LayoutSignature {
    pub fn of(point_names: &[String], skeleton: Option<&Animation>) -> Self {
        let mut h = blake3::Hasher::new();
        h.update(b"mocapstore-layout-v1\0");
        h.update(&(point_names.len() as u64).to_le_bytes());
        for name in point_names {
            // Length-prefixed so that ["ab","c"] and ["a","bc"] differ.
            h.update(&(name.len() as u64).to_le_bytes());
            h.update(name.as_bytes());
        }
        if let Some(s) = skeleton {
            h.update(b"skeleton\0");
            for j in &s.joints {
                let parent = j.parent.map_or(u64::MAX, |p| p as u64);
                h.update(&parent.to_le_bytes());
                h.update(&[u8::from(j.end_site), j.channels.len() as u8]);
                for c in &j.channels {
                    h.update(c.name().as_bytes());
                }
            }
        }
        let mut out = [0u8; 16];
        out.copy_from_slice(&h.finalize().as_bytes()[..16]);
        LayoutSignature(out)
    }

    pub fn to_hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }
}

impl fmt::Display for LayoutSignature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_hex())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn depends_on_names_and_their_order_only() {
        let a = LayoutSignature::of(&names(&["ab", "c"]), None);
        assert_eq!(a, LayoutSignature::of(&names(&["ab", "c"]), None));
        assert_ne!(a, LayoutSignature::of(&names(&["a", "bc"]), None));
        assert_ne!(a, LayoutSignature::of(&names(&["c", "ab"]), None));
        assert_eq!(a.to_hex().len(), 32);
    }
}
