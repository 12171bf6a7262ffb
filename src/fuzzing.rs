//! What the fuzz targets (`fuzz/fuzz_targets/`) run, kept in the crate so that the ordinary
//! test suite runs every input that ever crashed one of them (`tests/fuzz_regressions.rs`)
//! through exactly the same code. Each function takes untrusted bytes and may return
//! anything but a panic, an abort, a hang or unbounded memory. Not an API.

use std::sync::{Arc, OnceLock};

use crate::codec::container::{ChunkMeta, Header};
use crate::codec::lsdt::spatial::dct_basis;
use crate::codec::{self, Basis, BasisKind, CodecId, Container};
use crate::motion::formats::{self, Format, ReadLimits, ReadOptions};

/// ReadLimits for fuzzing: small enough that a legitimate allocation never trips the fuzzer's
/// memory limit, so that what it reports is a real failure to bound memory.
fn limits() -> ReadLimits {
    ReadLimits {
        max_bytes: 1 << 20,
        max_points: 1_000,
        max_frames: 100_000,
        max_samples: 1_000_000,
        max_depth: 512,
        max_analog_samples: 1_000_000,
    }
}

/// A reader of one format, strict and lenient.
pub fn read(format: Format, data: &[u8]) {
    for lenient in [false, true] {
        let opts = ReadOptions {
            limits: limits(),
            lenient,
            ..ReadOptions::default()
        };
        if let Ok(l) = formats::read_as(format, data, &opts) {
            // What was read can be written back.
            let out = if l.motion.skeleton.is_some() {
                Format::Bvh
            } else {
                Format::Trc
            };
            let _ = formats::write(&l.motion, out);
            if format == Format::C3d {
                // A C3D read whole is written whole, and that file reads again.
                let written = formats::c3d::write::write(&formats::c3d::write::Out {
                    motion: &l.motion,
                    analog: l.extras.analog.as_ref(),
                    outputs: l.extras.outputs.as_ref(),
                    parameters: l.extras.parameters.as_ref(),
                    first_frame: l.extras.first_frame.unwrap_or(1),
                });
                if let Ok(b) = written {
                    let back = formats::read_as(Format::C3d, &b, &ReadOptions::default())
                        .expect("a C3D we wrote reads back");
                    assert_eq!(back.motion.frame_count(), l.motion.frame_count());
                }
            }
        }
    }
}

/// The bases the frozen bitstreams (`tests/frozen/`) were coded with, so that seeds made from
/// them reach the decoders' inner loops: the DCT of 5 points (lsdt) and a two-basis
/// mdtt-set of 5 points.
fn frozen_bases() -> &'static [Arc<Basis>] {
    static BASES: OnceLock<Vec<Arc<Basis>>> = OnceLock::new();
    BASES.get_or_init(|| {
        [
            &include_bytes!(
                "../tests/frozen/bases/4700ede04fb6c2fd0cb1d3b94eedafc7bc47ca372bd35336647f2ee60bcd0b2a.mcsb"
            )[..],
            &include_bytes!(
                "../tests/frozen/bases/e92e07530c5e456efb979f265a2440352c26e631b0cbf69dd7fb6381b4df0546.mcsb"
            )[..],
        ]
        .iter()
        .map(|b| Arc::new(Basis::parse(b).expect("frozen bases parse")))
        .collect()
    })
}

/// A shared basis of `kind` for `points` points: a frozen one where there is one, else the
/// DCT (lsdt); `None` if there is none (an mdtt-set of another size).
fn basis_for(kind: BasisKind, points: usize) -> Option<Arc<Basis>> {
    if let Some(b) = frozen_bases()
        .iter()
        .find(|b| b.kind() == kind && b.points() == points)
    {
        return Some(b.clone());
    }
    (kind == BasisKind::Lsdt).then(|| Arc::new(dct_basis(points)))
}

/// The analog codecs' chunk decoder. `data`: channels (byte 0, 1..=16), frames (byte 1,
/// 1..=256), the parameter length (u16 LE), the parameters, then one chunk payload; the
/// header around them is made valid so that mutations reach the parameter parser and the
/// chunk decoder.
pub fn decode_analog(data: &[u8]) {
    if data.len() < 4 {
        return;
    }
    let channels = u32::from(data[0] % 16) + 1;
    let frames = u32::from(data[1]) + 1;
    let plen = usize::from(u16::from_le_bytes([data[2], data[3]]));
    let Some(params) = data.get(4..4 + plen) else {
        return;
    };
    let payload = &data[4 + plen..];
    for codec in CodecId::ANALOG {
        let header = Header {
            codec,
            frames,
            points: channels,
            fps: 60.0,
            metres_per_unit: 1.0,
            params: params.to_vec(),
            basis: None,
            rig: None,
            chunks: vec![ChunkMeta {
                first_frame: 0,
                frames,
                len: payload.len() as u32,
                crc32c: crc32c::crc32c(payload),
            }],
        };
        if let Ok(d) = codec::analog::Decoder::new(header) {
            // Per frame at most 64 Ki samples of 16 channels: bounded by the fuzzer's limits.
            if d.layout().per_frame <= 4096 {
                if let Ok(s) = d.decode_chunk(0, payload) {
                    assert_eq!(
                        s.len(),
                        frames as usize * d.layout().per_frame * channels as usize
                    );
                }
            }
        }
    }
}

/// A stored parameter section ([`formats::c3d::params::Parameters::from_section`]): what
/// parses is written again and reads back the same.
pub fn c3d_parameters(data: &[u8]) {
    use formats::c3d::params::Parameters;
    if let Ok(p) = Parameters::from_section(data) {
        if let Ok(again) = p.to_section() {
            let back = Parameters::from_section(&again).expect("a section we wrote parses");
            assert_eq!(back.groups.len(), p.groups.len());
        }
    }
}

/// One codec's chunk decoder. `data`: points (byte 0, 1..=16), frames (byte 1, 1..=256),
/// the parameter length (u16 LE), the parameters, then one chunk payload (gap mask and codec
/// bytes). The header around them is made valid (checksums included) so that the fuzzer's
/// mutations reach the parameter parser, the gap mask and the chunk decoder.
pub fn decode(codec: CodecId, data: &[u8]) {
    if data.len() < 4 {
        return;
    }
    let points = usize::from(data[0] % 16) + 1;
    let frames = usize::from(data[1]) + 1;
    let plen = usize::from(u16::from_le_bytes([data[2], data[3]]));
    let Some(params) = data.get(4..4 + plen) else {
        return;
    };
    let payload = &data[4 + plen..];
    let Ok(c) = codec::codec(codec) else {
        return;
    };
    let shared = match c.basis_kind() {
        None => None,
        Some(kind) => match basis_for(kind, points) {
            Some(b) => Some(b),
            None => return,
        },
    };
    let header = Header {
        codec,
        frames: frames as u32,
        points: points as u32,
        fps: 60.0,
        metres_per_unit: 0.001,
        params: params.to_vec(),
        basis: shared.as_ref().map(|b| b.hash()),
        rig: None,
        chunks: vec![ChunkMeta {
            first_frame: 0,
            frames: frames as u32,
            len: payload.len() as u32,
            crc32c: crc32c::crc32c(payload),
        }],
    };
    if let Ok(d) = codec::decoder(&header, &shared.into()) {
        let _ = codec::decode_chunk(&header, d.as_ref(), 0, payload);
    }
}

/// The skeleton the skeleton codecs' targets decode against: the synthetic dancer's, the one
/// the frozen `rot`, `pga` and `bvh-lossless` bitstreams (their seeds) were coded on.
fn dancer_rig() -> Arc<codec::Skeleton> {
    static RIG: OnceLock<Arc<codec::Skeleton>> = OnceLock::new();
    RIG.get_or_init(|| {
        let m = crate::motion::synthetic::dancer(2, 60.0, 11);
        let joints = m.skeleton.expect("the dancer has a skeleton").joints;
        Arc::new(codec::Skeleton::new(joints).expect("the dancer's skeleton is a rig"))
    })
    .clone()
}

/// A skeleton codec's chunk decoder (`rot`, `pga`, `bvh-lossless`) on [`dancer_rig`]: FK
/// positions when byte 0 is even, channel values (what BVH out reads) when it is odd. `data`
/// as for [`decode`], but the rig sets the points. One of the two per input, not both: the
/// positions path is the channels' whole decode plus FK (the channels path adds only the
/// reader's range plumbing), so both would double the work of an execution (pga's IK
/// decode makes it the slowest target) for little code the one alone misses.
pub fn decode_skeletal(codec: CodecId, data: &[u8]) {
    if data.len() < 4 {
        return;
    }
    let rig = dancer_rig();
    let frames = usize::from(data[1]) + 1;
    let plen = usize::from(u16::from_le_bytes([data[2], data[3]]));
    let Some(params) = data.get(4..4 + plen) else {
        return;
    };
    let payload = &data[4 + plen..];
    let header = Header {
        codec,
        frames: frames as u32,
        points: rig.joints().len() as u32,
        fps: 60.0,
        metres_per_unit: 0.01,
        params: params.to_vec(),
        basis: None,
        rig: Some(rig.hash()),
        chunks: vec![ChunkMeta {
            first_frame: 0,
            frames: frames as u32,
            len: payload.len() as u32,
            crc32c: crc32c::crc32c(payload),
        }],
    };
    let shared = codec::Shared {
        basis: None,
        rig: Some(rig.clone()),
    };
    let Ok(reader) = codec::Reader::new(header, shared) else {
        return;
    };
    let source = codec::Stored::new(0, [payload]);
    if data[0].is_multiple_of(2) {
        let _ = reader.read_all(&source);
    } else {
        let _ = reader.read_channels(0..frames, rig.channel_count(), &source);
    }
}

/// A whole stored bitstream (container): header, index, checksums, every chunk.
pub fn container(data: &[u8]) {
    let limits = crate::codec::DecodeLimits {
        max_samples: 1_000_000,
        ..crate::codec::DecodeLimits::default()
    };
    let Ok(c) = Container::parse(data, &limits) else {
        return;
    };
    let shared = c.header.basis.and_then(|h| {
        frozen_bases()
            .iter()
            .find(|b| b.hash() == h)
            .cloned()
            .or_else(|| {
                // A DCT of a small layout (a large one would be the fuzzer's allocation).
                let points = c.header.points as usize;
                let b = (points <= 64).then(|| Arc::new(dct_basis(points)))?;
                (b.hash() == h).then_some(b)
            })
    });
    let _ = codec::decode_all_with(&c, shared);
}

/// Every parser of request input (queries, headers, JSON and f32 bodies).
pub fn requests(data: &[u8]) {
    crate::http::fuzz::requests(data);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_frozen_bases_load_and_short_inputs_are_harmless() {
        assert_eq!(frozen_bases().len(), 2);
        for c in CodecId::ALL {
            decode(c, &[]);
            decode(c, &[4, 9, 0, 0]);
            decode(c, &[4, 9, 3, 0, 1, 2, 3, 0, 0]);
        }
        container(b"MCST");
        requests(b"start=1&end=0\0{\"frames\":[[1,null]]}");
        read(Format::Bvh, b"HIERARCHY\nROOT a\n{");
    }
}
