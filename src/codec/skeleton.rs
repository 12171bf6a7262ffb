//! Skeletons stored once: a joint hierarchy (names, parents, offsets, channel lists in their
//! rotation orders, End Sites), content addressed like a shared basis and referenced by every
//! take of it.
//!
//! Why a stored object and not per-take metadata: a take of 130 frames coded at 1 mm takes
//! ~3 KB, and the hierarchy of a 50-joint rig as JSON took as much again in every row. Codecs
//! that keep channel values ([`super::Codec::codes_channels`]) need the hierarchy to turn
//! decoded channels into positions (FK), so their headers name the rig by hash and a decoder
//! is built only with the rig of that hash.
//!
//! # Format
//! `"MCSK"`, version u16, joint count u32; per joint, parents first: name length u16 and
//! UTF-8 bytes, parent index u32 (`u32::MAX` for the root), flags u8 (bit 0: End Site),
//! offset 3 × f64, channel count u8, one byte per channel (0–2: X/Y/Z position, 3–5: X/Y/Z
//! rotation). All little-endian. The id is the BLAKE3 hash of these bytes (hex).
//!
//! Version 2 (a rig uploaded on its own, `POST /v1/skeletons`) follows the joints with
//! what a take's skeleton does not need: flags u8 (bit 0: a rest pose, bit 1: a
//! character), then the rest pose's channel values (one f64 per channel, in file order:
//! the bind pose of a glTF character, whose joints rest turned) and the BLAKE3 hash of the
//! character file (32 bytes) whose mesh the rig skins. An uploaded rig is always version
//! 2, even with neither, so that its id never is a take's skeleton's (whose row, library
//! and uses are not the uploader's to see); a take's skeleton stays version 1.

use super::basis::hex;
use super::error::{malformed, Error, Result};
use super::wire::{Reader, Writer};
use crate::motion::decimal::PrintedValues;
use crate::motion::skeleton::{Animation, Channel, Fk, Joint};

const MAGIC: &[u8; 4] = b"MCSK";
const VERSION: u16 = 1;
/// The version of a rig with a rest pose or a character.
const VERSION_UPLOADED: u16 = 2;
const HAS_REST: u8 = 1;
const HAS_CHARACTER: u8 = 2;
const CHANNELS: [Channel; 6] = [
    Channel::Xposition,
    Channel::Yposition,
    Channel::Zposition,
    Channel::Xrotation,
    Channel::Yrotation,
    Channel::Zrotation,
];

/// A joint hierarchy with its canonical bytes and content hash.
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    joints: Vec<Joint>,
    channels: usize,
    /// Channel values of the rest pose, when it is not the offsets' (rotations zero).
    rest: Option<Vec<f64>>,
    /// BLAKE3 of the character file whose mesh the rig skins.
    character: Option<[u8; 32]>,
    bytes: Vec<u8>,
    hash: [u8; 32],
}

impl Skeleton {
    /// The rig of these joints, checked as a skeleton is (parents first, one root, no
    /// channels on End Sites).
    pub fn new(joints: Vec<Joint>) -> Result<Skeleton> {
        Skeleton::build(joints, None, None, false)
    }

    /// An uploaded rig (version 2), standing in `rest` (channel values, one per channel;
    /// finite) where given, and skinning the character file of hash `character`.
    pub fn uploaded(
        joints: Vec<Joint>,
        rest: Option<Vec<f64>>,
        character: Option<[u8; 32]>,
    ) -> Result<Skeleton> {
        Skeleton::build(joints, rest, character, true)
    }

    fn build(
        joints: Vec<Joint>,
        rest: Option<Vec<f64>>,
        character: Option<[u8; 32]>,
        uploaded: bool,
    ) -> Result<Skeleton> {
        let joints = Animation::new(joints, Vec::new())
            .map_err(|e| Error::Invalid(format!("skeleton: {e}")))?
            .joints;
        if joints.is_empty() {
            return Err(Error::Invalid("a skeleton without joints".into()));
        }
        let channels: usize = joints.iter().map(|j| j.channels.len()).sum();
        if let Some(r) = &rest {
            if r.len() != channels {
                return Err(Error::Invalid(format!(
                    "a rest pose of {} values for {channels} channels",
                    r.len()
                )));
            }
            if r.iter().any(|v| !v.is_finite()) {
                return Err(Error::Invalid("a rest pose value is not finite".into()));
            }
        }
        let uploaded = uploaded || rest.is_some() || character.is_some();
        let version = if uploaded { VERSION_UPLOADED } else { VERSION };
        let mut w = Writer::new();
        w.bytes(MAGIC).bytes(&version.to_le_bytes());
        w.u32(joints.len() as u32);
        for j in &joints {
            let name = j.name.as_bytes();
            let len = u16::try_from(name.len())
                .map_err(|_| Error::Invalid(format!("joint name of {} bytes", name.len())))?;
            w.bytes(&len.to_le_bytes()).bytes(name);
            w.u32(j.parent.map_or(u32::MAX, |p| p as u32));
            w.bytes(&[u8::from(j.end_site)]);
            for v in j.offset {
                w.f64(v);
            }
            w.bytes(&[j.channels.len() as u8]);
            for c in &j.channels {
                let code = CHANNELS.iter().position(|k| k == c).expect("every channel");
                w.bytes(&[code as u8]);
            }
        }
        if uploaded {
            let flags = if rest.is_some() { HAS_REST } else { 0 }
                | if character.is_some() {
                    HAS_CHARACTER
                } else {
                    0
                };
            w.bytes(&[flags]);
            for v in rest.iter().flatten() {
                w.f64(*v);
            }
            if let Some(h) = &character {
                w.bytes(h);
            }
        }
        let bytes = w.0;
        let hash = *blake3::hash(&bytes).as_bytes();
        Ok(Skeleton {
            joints,
            channels,
            rest,
            character,
            bytes,
            hash,
        })
    }

    /// Parse stored bytes; at most `max_joints` joints are allocated.
    pub fn parse(bytes: &[u8], max_joints: u64) -> Result<Skeleton> {
        let mut r = Reader::named(bytes, "skeleton");
        if r.take(4)? != MAGIC {
            return Err(malformed("not a mocapstore skeleton (bad magic)"));
        }
        let version = r.u16()?;
        if version != VERSION && version != VERSION_UPLOADED {
            return Err(Error::Unsupported(format!("skeleton version {version}")));
        }
        let n = r.u32()?;
        if u64::from(n) > max_joints {
            return Err(Error::Limit {
                what: "joint count",
                actual: n.into(),
                limit: max_joints,
            });
        }
        // Each joint takes at least 32 bytes, so a forged count cannot make us allocate.
        let mut joints = Vec::with_capacity((n as usize).min(bytes.len() / 32));
        for _ in 0..n {
            let len = r.u16()?;
            let name = std::str::from_utf8(r.take(len.into())?)
                .map_err(|_| malformed("a joint name is not UTF-8"))?
                .to_string();
            let parent = match r.u32()? {
                u32::MAX => None,
                p => Some(p as usize),
            };
            let end_site = match r.u8()? {
                0 => false,
                1 => true,
                f => return Err(malformed(format!("joint flags {f:#x}"))),
            };
            let offset = [r.f64()?, r.f64()?, r.f64()?];
            if offset.iter().any(|v| !v.is_finite()) {
                return Err(malformed("a joint offset is not finite"));
            }
            let count = r.u8()?;
            let mut channels = Vec::with_capacity(usize::from(count.min(6)));
            for _ in 0..count {
                let c = r.u8()?;
                channels.push(
                    *CHANNELS
                        .get(usize::from(c))
                        .ok_or_else(|| malformed(format!("channel code {c}")))?,
                );
            }
            joints.push(Joint {
                name,
                parent,
                offset,
                channels,
                end_site,
            });
        }
        let (mut rest, mut character) = (None, None);
        if version == VERSION_UPLOADED {
            let flags = r.u8()?;
            if flags & !(HAS_REST | HAS_CHARACTER) != 0 {
                return Err(malformed(format!("skeleton flags {flags:#x}")));
            }
            if flags & HAS_REST != 0 {
                let n: usize = joints.iter().map(|j| j.channels.len()).sum();
                let mut v = Vec::with_capacity(n.min(bytes.len() / 8));
                for _ in 0..n {
                    v.push(r.f64()?);
                }
                rest = Some(v);
            }
            if flags & HAS_CHARACTER != 0 {
                character = Some(r.take(32)?.try_into().expect("32 bytes"));
            }
        }
        r.finish()?;
        let rig = Skeleton::build(joints, rest, character, version == VERSION_UPLOADED)
            .map_err(|e| malformed(e.to_string()))?;
        if rig.bytes != bytes {
            return Err(malformed("skeleton bytes are not in canonical form"));
        }
        Ok(rig)
    }

    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    /// Channel values of the pose the rig stands in when nothing moves it: an uploaded
    /// rig's bind pose, else its offsets' ([`crate::motion::skeleton::rest_values`]).
    pub fn rest(&self) -> Vec<f64> {
        self.rest
            .clone()
            .unwrap_or_else(|| crate::motion::skeleton::rest_values(&self.joints))
    }

    /// The hash (hex) of the character file whose mesh this rig skins, if it came with one.
    pub fn character(&self) -> Option<String> {
        self.character.as_ref().map(hex)
    }

    /// Channel values per frame.
    pub fn channel_count(&self) -> usize {
        self.channels
    }

    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    pub fn hash(&self) -> [u8; 32] {
        self.hash
    }

    /// The id under which it is stored: the hash in hex.
    pub fn id(&self) -> String {
        hex(&self.hash)
    }

    /// Joint positions (`frames × joints × 3`, f32) of channel values
    /// (`frames × channel_count()`), by the same FK as reading the file: a decoder that
    /// gives back the values ingest read gives back the positions ingest measured.
    pub fn positions(&self, values: &[f64], out: &mut [f32]) {
        let (cc, w) = (self.channels, self.joints.len() * 3);
        let mut fk = Fk::new(&self.joints);
        let mut frame = vec![0f64; w];
        for (vals, to) in values.chunks_exact(cc.max(1)).zip(out.chunks_exact_mut(w)) {
            fk.frame(&self.joints, vals, &mut frame);
            for (t, v) in to.iter_mut().zip(&frame) {
                *t = *v as f32;
            }
        }
    }
}

/// Channel values of some frames, as a codec that keeps them decodes them: values in file
/// order (`frames × channels`), and for a lossless codec the characters they were printed
/// with.
#[derive(Debug, Clone, PartialEq)]
pub struct Channels {
    pub values: Vec<f64>,
    pub printed: Option<PrintedValues>,
}

/// Lossy codecs round decoded channel values to this many per unit (degrees, file units):
/// six decimals, what a BVH file prints.
const PRINTED: f64 = 1e6;

/// A decoded channel value as a BVH file prints it. Codecs that keep channel values round
/// what they decode with this, so the bound they verify on decoding holds on the served
/// file.
pub fn printed(v: f64) -> f64 {
    (v * PRINTED).round() / PRINTED
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::synthetic::chain_bvh;

    fn rig() -> Skeleton {
        let m = crate::motion::formats::read(chain_bvh(5).as_bytes(), &Default::default())
            .unwrap()
            .motion;
        Skeleton::new(m.skeleton.unwrap().joints).unwrap()
    }

    #[test]
    fn parses_back_to_the_same_rig_and_refuses_damage() {
        let r = rig();
        let again = Skeleton::parse(r.bytes(), 100).unwrap();
        assert_eq!(again, r);
        assert_eq!(r.id().len(), 64);
        assert!(matches!(
            Skeleton::parse(r.bytes(), 2),
            Err(Error::Limit { .. })
        ));
        for cut in 0..r.bytes().len() {
            assert!(Skeleton::parse(&r.bytes()[..cut], 100).is_err());
        }
        for i in 0..r.bytes().len() {
            let mut b = r.bytes().to_vec();
            b[i] ^= 0x5a;
            // Either refused, or a different rig (a changed name or offset).
            if let Ok(other) = Skeleton::parse(&b, 100) {
                assert_ne!(other.hash(), r.hash());
            }
        }
    }

    /// An uploaded rig keeps its rest pose and character through its bytes; with neither
    /// it is still version 2, never the id of a take's skeleton of the same joints.
    #[test]
    fn an_uploaded_rig_keeps_its_rest_and_character() {
        let plain = rig();
        let joints = plain.joints().to_vec();
        let rest: Vec<f64> = (0..plain.channel_count()).map(|i| i as f64 * 0.5).collect();
        let up = Skeleton::uploaded(joints.clone(), Some(rest.clone()), Some([7; 32])).unwrap();
        assert_eq!(u16::from_le_bytes([up.bytes()[4], up.bytes()[5]]), 2);
        let again = Skeleton::parse(up.bytes(), 100).unwrap();
        assert_eq!(again.rest(), rest);
        assert_eq!(again.character(), Some(hex(&[7; 32])));
        assert_ne!(up.id(), plain.id());
        let bare = Skeleton::uploaded(joints.clone(), None, None).unwrap();
        assert_ne!(bare.id(), plain.id());
        assert_eq!(Skeleton::parse(bare.bytes(), 100).unwrap(), bare);
        assert_eq!(bare.rest(), plain.rest());
        assert_eq!(plain.rest(), crate::motion::skeleton::rest_values(&joints));
        assert!(Skeleton::uploaded(joints.clone(), Some(vec![0.0]), None).is_err());
        assert!(Skeleton::uploaded(joints, Some(vec![f64::NAN; rest.len()]), None).is_err());
        for cut in 0..up.bytes().len() {
            assert!(Skeleton::parse(&up.bytes()[..cut], 100).is_err());
        }
    }
}
