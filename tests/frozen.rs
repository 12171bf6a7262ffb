//! What is stored today decodes tomorrow: small bitstreams written by past encoders are kept
//! in `tests/frozen/` with the BLAKE3 of what they decoded to when written, and every one must
//! still decode to exactly that. The golden test (`tests/golden.rs`) pins what encoders write
//! now; this one pins what decoders must go on reading.
//!
//! A format or parameter version change *adds* files (`MOCAPSTORE_FREEZE=1 cargo test --test
//! frozen -- --ignored` writes those of the current encoders that are missing); a file here is
//! never replaced or deleted, since a database somewhere holds takes coded that way.
//!
//! `index.txt`: one line per file: `<file> <hash of the decoded f32 bytes> <what it is>`.
//! Bases a bitstream names sit in `tests/frozen/bases/<id>.mcsb`, skeletons in
//! `tests/frozen/skeletons/<id>.mcsk`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use mocapstore::codec::container::pack_chunks;
use mocapstore::codec::lsdt::spatial::dct_basis;
use mocapstore::codec::lsdt::{clip, frame};
use mocapstore::codec::mdtt::database::{train_bases, SetOptions};
use mocapstore::codec::pga::encode::{Directions, Options, Take};
use mocapstore::codec::{self, Basis, CodecId, Container, ErrorBound, Header, Limits};
use mocapstore::motion::analog::Samples;
use mocapstore::motion::synthetic::{force_and_emg, two_behaviours, walker};
use mocapstore::motion::Motion;

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/frozen")
}

/// Decoded frames as bytes, hashed.
fn digest(frames: &[f32]) -> String {
    let bytes: Vec<u8> = frames.iter().flat_map(|v| v.to_le_bytes()).collect();
    blake3::hash(&bytes).to_hex()[..32].to_string()
}

/// An analog container's stored values, as f32 (16-bit integers are exact in one).
fn decode_analog(c: &Container) -> Vec<f32> {
    match codec::analog::decode_all(c).unwrap().samples {
        Samples::Int { values, .. } => values.iter().map(|&v| v as f32).collect(),
        Samples::Float(v) => v,
    }
}

fn decode_file(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let c = Container::parse(&bytes, &Limits::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    if c.header.codec.is_analog() {
        return decode_analog(&c);
    }
    let basis = c.header.basis.map(|h| {
        let id = codec::basis::hex(&h);
        let b = std::fs::read(dir().join("bases").join(format!("{id}.mcsb")))
            .unwrap_or_else(|e| panic!("{}: basis {id}: {e}", path.display()));
        Arc::new(Basis::parse(&b).unwrap())
    });
    let rig = c.header.rig.map(|h| {
        let id = codec::basis::hex(&h);
        let b = std::fs::read(dir().join("skeletons").join(format!("{id}.mcsk")))
            .unwrap_or_else(|e| panic!("{}: skeleton {id}: {e}", path.display()));
        Arc::new(codec::Rig::parse(&b, 10_000).unwrap())
    });
    codec::decode_all_with(&c, codec::Shared { basis, rig })
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// (file, hash, description) of every line of the index.
fn index() -> Vec<(String, String, String)> {
    let text = std::fs::read_to_string(dir().join("index.txt")).unwrap_or_default();
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let mut parts = l.splitn(3, ' ');
            let file = parts.next().unwrap().to_string();
            let hash = parts.next().expect("hash").to_string();
            (file, hash, parts.next().unwrap_or("").to_string())
        })
        .collect()
}

/// Every codec, and every parameter version its decoder accepts, has a frozen bitstream.
const REQUIRED: &[&str] = &[
    "raw",
    "quant",
    "quant-v2",
    "mdtt",
    "mdtt-shared-v1",
    "lsdt-clip-v1",
    "lsdt-clip-v2",
    "lsdt-frame-v1",
    "lsdt-frame-v2",
    "lsdt-frame-v3",
    "bvh-lossless-v1",
    "rot-v1",
    "rot-v2",
    "pga-v1",
    "pga-v1-plain",
    "pga-v1-ik",
    "pga-v1-canonical",
    "spca-v1",
    "spca-v1-torso",
    "analog-lossless-v1-int",
    "analog-lossless-v1-float",
    "analog-bounded-v1-int",
];

#[test]
fn every_frozen_bitstream_decodes_to_what_it_decoded_to_when_written() {
    let index = index();
    for want in REQUIRED {
        assert!(
            index.iter().any(|(f, _, _)| f.starts_with(&format!("{want}-")) || f == &format!("{want}.mcst")),
            "no frozen bitstream for {want}: freeze one (see the module doc)"
        );
    }
    for (file, hash, what) in &index {
        let got = digest(&decode_file(&dir().join(file)));
        assert_eq!(&got, hash, "{file} ({what}) no longer decodes as it did");
    }
}

/// The small take every frozen bitstream codes: 2 s, 5 points, some gaps.
fn take() -> Motion {
    walker(120, 5, 60.0, 11, 0.05)
}

/// A container of chunks coded by a live stream's adaptive stage.
fn stream_container(
    m: &Motion,
    codec: CodecId,
    params: Vec<u8>,
    basis: &Basis,
    chunks: Vec<codec::ChunkOut>,
) -> Container {
    let valid: Vec<bool> = m
        .positions()
        .chunks_exact(3)
        .map(|s| !s[0].is_nan())
        .collect();
    let (metas, payloads, frames) = pack_chunks(chunks, Some(&valid), m.point_count());
    Container {
        header: Header {
            codec,
            frames: frames as u32,
            points: m.point_count() as u32,
            fps: m.fps,
            metres_per_unit: m.unit.metres_per_unit,
            params,
            basis: Some(basis.hash()),
            rig: None,
            chunks: metas,
        },
        chunks: payloads,
    }
}

/// Write the bitstreams of today's encoders that are not frozen yet (never overwriting).
#[test]
#[ignore = "writes tests/frozen/; run with MOCAPSTORE_FREEZE=1 after a format change"]
fn freeze_current_bitstreams() {
    if std::env::var("MOCAPSTORE_FREEZE").as_deref() != Ok("1") {
        eprintln!("set MOCAPSTORE_FREEZE=1 to write frozen bitstreams");
        return;
    }
    let m = take();
    let dct = Arc::new(dct_basis(m.point_count()));
    let filled = codec::gaps::fill(m.positions(), m.point_count());
    let valid: Vec<bool> = m
        .positions()
        .chunks_exact(3)
        .map(|s| !s[0].is_nan())
        .collect();
    let input = |shared| codec::Input {
        data: &filled,
        valid: Some(&valid),
        frames: m.frame_count(),
        points: m.point_count(),
        fps: m.fps,
        shared,
        skeleton: None,
        names: &[],
        torso: None,
    };
    let set = Arc::new(train_bases(&[input(None)], 2, &SetOptions::default()).unwrap());
    let bound = ErrorBound::max(1.0);
    let mut out: Vec<(String, Container, Option<Arc<Basis>>, String)> = Vec::new();
    for (codec, basis) in [
        (CodecId::Raw, None),
        (CodecId::Quant, None),
        (CodecId::Mdtt, None),
        (CodecId::MdttShared, Some(set.clone())),
        (CodecId::LsdtClip, Some(dct.clone())),
        (CodecId::LsdtFrame, Some(dct.clone())),
        (CodecId::Spca, None),
    ] {
        let enc = codec::encode_with(&m, codec, bound, basis.as_ref()).unwrap();
        let c = enc.container;
        let version = match codec {
            CodecId::Raw | CodecId::Quant | CodecId::Mdtt => String::new(),
            _ => format!("-v{}", c.header.params[0]),
        };
        out.push((
            format!("{codec}{version}"),
            c,
            basis,
            format!("{codec} batch, {bound}"),
        ));
    }
    // quant's parameters version 2 (rANS tables), which the encoder keeps where it codes
    // smaller.
    let enc = codec::encode_variant(&m, CodecId::Quant, bound, None, |i, t| {
        codec::quant::encode_version(i, t, Some(2))
    })
    .unwrap();
    out.push((
        "quant-v2".into(),
        enc.container,
        None,
        format!("quant batch, parameters version 2, {bound}"),
    ));
    // The live streams' adaptive stages.
    let t = 1.0 / m.unit.to_mm();
    let p = frame::stream_params(t, m.fps);
    let mut e = frame::FrameEncoder::new(p, &dct).unwrap();
    let mut chunks = Vec::new();
    // As a stream codes them: frames as sent, NaN where a sample is missing.
    for f in m.positions().chunks_exact(m.point_count() * 3) {
        chunks.extend(e.push(f, None).1);
    }
    chunks.extend(e.finish());
    let c = stream_container(&m, CodecId::LsdtFrame, p.to_bytes(), &dct, chunks);
    out.push((
        "lsdt-frame-v1".into(),
        c,
        Some(dct.clone()),
        "lsdt-frame live stream, max 1 mm".into(),
    ));
    let p = clip::stream_params(t, m.fps);
    let chunks = clip::encode_fixed(&input(Some(&dct)), p).unwrap();
    let c = stream_container(&m, CodecId::LsdtClip, p.to_bytes(), &dct, chunks);
    out.push((
        "lsdt-clip-v1".into(),
        c,
        Some(dct.clone()),
        "lsdt-clip live stream, max 1 mm".into(),
    ));

    // The codecs that keep a skeleton's channels, on a small BVH take.
    let bvh = mocapstore::motion::synthetic::dancer(150, 60.0, 11);
    let rig = Arc::new(codec::Rig::new(bvh.skeleton.clone().unwrap().joints).unwrap());
    std::fs::create_dir_all(dir().join("skeletons")).unwrap();
    std::fs::write(
        dir().join("skeletons").join(format!("{}.mcsk", rig.id())),
        rig.bytes(),
    )
    .unwrap();
    let mut skeletal = Vec::new();
    for codec in [CodecId::BvhLossless, CodecId::Rot, CodecId::Pga] {
        let c = codec::encode(&bvh, codec, bound).unwrap().container;
        let name = format!("{codec}-v{}", c.header.params[0]);
        skeletal.push((
            name,
            c,
            format!("{codec} batch, {bound}, a dancer BVH take"),
        ));
    }
    // `pga`'s two decoder paths on their own: poses from coordinates alone, and IK.
    let ik = Options {
        iterations: 3,
        ..Options::IK
    };
    for (name, directions, options, what) in [
        (
            "plain",
            Directions::Principal,
            Options::PLAIN,
            "poses from coordinates alone",
        ),
        ("ik", Directions::Principal, ik, "decoded by IK (3 steps)"),
        (
            "canonical",
            Directions::Canonical,
            Options::PLAIN,
            "the canonical model (means only)",
        ),
    ] {
        let c = codec::encode_variant(&bvh, CodecId::Pga, bound, None, |input, t| {
            let (rig, sk) = input.skeleton.unwrap();
            Take::new(rig, sk, input)?.encode(t, &[directions], &[options])
        })
        .unwrap()
        .container;
        skeletal.push((
            format!("pga-v{}-{name}", c.header.params[0]),
            c,
            format!("pga batch {what}, {bound}, a dancer BVH take"),
        ));
    }

    // `spca` with its torso normalisation, segments and blends.
    let c = codec::encode(&two_behaviours(), CodecId::Spca, bound)
        .unwrap()
        .container;
    out.push((
        format!("spca-v{}-torso", c.header.params[0]),
        c,
        None,
        "spca batch, max 1 mm, normalised by the torso, two segments blended".into(),
    ));

    let mut index = std::fs::read_to_string(dir().join("index.txt")).unwrap_or_else(|_| {
        "# file, BLAKE3 (first 32 hex) of the decoded frames as little-endian f32, what it is\n"
            .into()
    });
    std::fs::create_dir_all(dir().join("bases")).unwrap();
    for (name, c, basis, what) in out {
        let file = format!("{name}.mcst");
        if index.lines().any(|l| l.starts_with(&format!("{file} "))) {
            continue;
        }
        if let Some(b) = &basis {
            std::fs::write(
                dir().join("bases").join(format!("{}.mcsb", b.id())),
                b.bytes(),
            )
            .unwrap();
        }
        std::fs::write(dir().join(&file), c.to_bytes()).unwrap();
        let decoded = codec::decode_all_with(&c, basis).unwrap();
        index.push_str(&format!("{file} {} {what}\n", digest(&decoded)));
        eprintln!("froze {file}");
    }
    for (name, c, what) in skeletal {
        let file = format!("{name}.mcst");
        if index.lines().any(|l| l.starts_with(&format!("{file} "))) {
            continue;
        }
        std::fs::write(dir().join(&file), c.to_bytes()).unwrap();
        let shared = codec::Shared {
            basis: None,
            rig: Some(rig.clone()),
        };
        let decoded = codec::decode_all_with(&c, shared).unwrap();
        index.push_str(&format!("{file} {} {what}\n", digest(&decoded)));
        eprintln!("froze {file}");
    }
    // The analog codecs: a force plate and EMG as ADC integers and as floats (on a grid,
    // and not), and within bounds.
    let analog = [
        (
            "analog-lossless-v1-int",
            force_and_emg(60, 10, 3, "int"),
            vec![],
        ),
        (
            "analog-lossless-v1-float",
            force_and_emg(60, 10, 3, "float"),
            vec![],
        ),
        (
            "analog-bounded-v1-int",
            force_and_emg(60, 10, 3, "int"),
            vec![
                Some(2.0),
                Some(2.0),
                Some(5.0),
                None,
                None,
                None,
                Some(0.01),
                None,
            ],
        ),
    ];
    for (name, a, bounds) in analog {
        let file = format!("{name}.mcst");
        if index.lines().any(|l| l.starts_with(&format!("{file} "))) {
            continue;
        }
        let c = codec::analog::encode(&a, 100.0, &[32, 28], &bounds)
            .unwrap()
            .container;
        std::fs::write(dir().join(&file), c.to_bytes()).unwrap();
        let what = format!(
            "{}, 8 channels (force plate, EMG) × 600 rows",
            c.header.codec
        );
        index.push_str(&format!("{file} {} {what}\n", digest(&decode_analog(&c))));
        eprintln!("froze {file}");
    }
    std::fs::write(dir().join("index.txt"), index).unwrap();
}
