//! What is stored today decodes tomorrow: small bitstreams written by past encoders are kept
//! in `tests/frozen/` with the BLAKE3 of what they decoded to when written, and every one must
//! still decode to exactly that. The golden test (`tests/golden.rs`) pins what encoders write
//! now; this one pins what decoders must go on reading.
//!
//! A format or parameter version change *adds* files (`MOCAPSTORE_FREEZE=1 cargo test --test
//! frozen -- --ignored` writes those of the current encoders that are missing); a file here is
//! never replaced or deleted, since a database somewhere holds takes coded that way
//! (`tests/frozen/README.md`). The test holds the directory to that: every file is in the
//! index with the BLAKE3 of its bytes, and every parameter version each codec's decoder
//! accepts ([`Codec::versions`], from the code) has a file that is that version.
//!
//! `index.txt`: one line per file: `<file> <BLAKE3 of its bytes> <BLAKE3 of the decoded f32
//! bytes> <what it is>` (each hash its first 32 hex digits). Bases a bitstream names sit in
//! `tests/frozen/bases/<id>.mcsb`, skeletons in `tests/frozen/skeletons/<id>.mcsk`, each
//! named by its own content hash.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use mocapstore::codec::container::pack_chunks;
use mocapstore::codec::lsdt::spatial::dct_basis;
use mocapstore::codec::lsdt::{clip, frame};
use mocapstore::codec::mdtt::database::{train_bases, SetOptions};
use mocapstore::codec::pga::encode::{Directions, Options, Take};
use mocapstore::codec::{self, Basis, CodecId, Container, DecodeLimits, ErrorBound, Header};
use mocapstore::motion::analog::Samples;
use mocapstore::motion::formats::bvh::ChannelWriter;
use mocapstore::motion::synthetic::{force_and_emg, two_behaviours, walker};
use mocapstore::motion::Motion;

#[path = "support/scalar.rs"]
mod scalar;

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/frozen")
}

/// Decoded frames as bytes, hashed.
fn digest(frames: &[f32]) -> String {
    let bytes: Vec<u8> = frames.iter().flat_map(|v| v.to_le_bytes()).collect();
    short_hash(&bytes)
}

/// The first 32 hex digits of the BLAKE3 of `bytes`.
fn short_hash(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex()[..32].to_string()
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
    let c = Container::parse(&bytes, &DecodeLimits::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    if c.header.codec.is_analog() {
        return decode_analog(&c);
    }
    codec::decode_all_with(&c, shared_of(&c, path))
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The basis and skeleton a frozen container names, from `bases/` and `skeletons/`.
fn shared_of(c: &Container, path: &Path) -> codec::Shared {
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
        Arc::new(codec::Skeleton::parse(&b, 10_000).unwrap())
    });
    codec::Shared { basis, rig }
}

/// Deterministic ranges `start..end` within `frames` (a small LCG, seeded per file).
fn ranges(frames: usize, seed: u64, n: usize) -> Vec<std::ops::Range<usize>> {
    let mut x = seed | 1;
    let mut next = |m: usize| {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((x >> 33) as usize) % m.max(1)
    };
    let mut out = vec![0..frames, 0..1, frames - 1..frames];
    for _ in 0..n {
        let a = next(frames);
        let b = a + 1 + next(frames - a);
        out.push(a..b);
    }
    out
}

/// Every frozen bitstream read by ranges (any points, any chunks) gives the same values as
/// the same rows of its whole decode, bit for bit, gaps included; channel codecs give the
/// same channel values by range as whole.
#[test]
fn every_frozen_bitstream_reads_any_range_as_the_same_rows_of_the_whole() {
    scalar::in_child();
    let mut gaps = false;
    for e in index() {
        let path = dir().join(&e.file);
        let c = Container::parse(&std::fs::read(&path).unwrap(), &DecodeLimits::default()).unwrap();
        if c.header.codec.is_analog() {
            continue;
        }
        let shared = shared_of(&c, &path);
        let rig = shared.rig.clone();
        let reader = codec::Reader::new(c.header.clone(), shared).unwrap();
        let source = codec::Stored::new(0, c.chunks.iter().map(Vec::as_slice));
        let whole = reader.read_all(&source).unwrap();
        gaps |= whole.iter().any(|v| v.is_nan());
        let (frames, points) = (c.header.frames as usize, c.header.points as usize);
        let w = points * 3;
        let seed = e
            .bytes
            .bytes()
            .fold(0u64, |h, b| h.wrapping_mul(31) ^ u64::from(b));
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for r in ranges(frames, seed, 12) {
            let got = reader.read(r.clone(), None, &source).unwrap();
            assert_eq!(
                bits(&got),
                bits(&whole[r.start * w..r.end * w]),
                "{}: frames {r:?}",
                e.file
            );
            // Some points, out of order.
            let picked: Vec<usize> = (0..points).rev().step_by(2).collect();
            let got = reader.read(r.clone(), Some(&picked), &source).unwrap();
            let want: Vec<f32> = whole[r.start * w..r.end * w]
                .chunks_exact(w)
                .flat_map(|f| {
                    picked
                        .iter()
                        .flat_map(move |&p| f[p * 3..p * 3 + 3].to_vec())
                })
                .collect();
            assert_eq!(bits(&got), bits(&want), "{}: points of {r:?}", e.file);
        }
        let Some(rig) = rig.filter(|_| codec::codec(c.header.codec).unwrap().codes_channels())
        else {
            continue;
        };
        let n = rig.channel_count();
        let all = reader.read_channels(0..frames, n, &source).unwrap().values;
        for r in ranges(frames, seed ^ 7, 8) {
            let got = reader.read_channels(r.clone(), n, &source).unwrap().values;
            assert_eq!(
                got,
                all[r.start * n..r.end * n],
                "{}: channels {r:?}",
                e.file
            );
        }
    }
    assert!(gaps, "some frozen takes have gaps");
}

/// `channels.txt`: per frozen take of a codec that keeps a skeleton's channels, the BLAKE3 of
/// its channel values (f64, little-endian) and of the BVH text written from them (what
/// `GET …/frames?format=bvh` serves: the digits `bvh-lossless` kept, six decimals for the
/// others). The freezer adds a new file's line ([`add_channel_lines`]); a line never changes.
const CHANNELS: &str = "channels.txt";

/// The channel values and BVH text of frozen take `file`, hashed; `None` for a take of a
/// codec that keeps positions only.
fn channel_hashes(file: &str) -> Option<(String, String)> {
    let path = dir().join(file);
    let c = Container::parse(&std::fs::read(&path).unwrap(), &DecodeLimits::default()).unwrap();
    if c.header.codec.is_analog() || !codec::codec(c.header.codec).unwrap().codes_channels() {
        return None;
    }
    let shared = shared_of(&c, &path);
    let rig = shared
        .rig
        .clone()
        .expect("a channel codec names a skeleton");
    let reader = codec::Reader::new(c.header.clone(), shared).unwrap();
    let source = codec::Stored::new(0, c.chunks.iter().map(Vec::as_slice));
    let frames = c.header.frames as usize;
    let ch = reader
        .read_channels(0..frames, rig.channel_count(), &source)
        .unwrap();
    let values: Vec<u8> = ch.values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let w = ChannelWriter::new(rig.joints().to_vec(), c.header.fps, frames);
    let mut bvh = Vec::new();
    w.head(&mut bvh);
    w.frames(&ch.values, ch.printed.as_ref(), 0..frames, &mut bvh);
    Some((short_hash(&values), short_hash(&bvh)))
}

/// Every frozen take of a channel codec reads as the same channel values and BVH text as
/// when it was frozen (`channels.txt`), so the BVH-out path and `bvh-lossless`'s printed
/// digits cannot drift.
#[test]
fn every_frozen_channel_take_reads_as_the_same_channels_and_bvh_text() {
    let text = std::fs::read_to_string(dir().join(CHANNELS)).unwrap();
    let mut checked = Vec::new();
    for e in index() {
        let Some((values, bvh)) = channel_hashes(&e.file) else {
            continue;
        };
        let line = text
            .lines()
            .find(|l| l.split(' ').next() == Some(e.file.as_str()))
            .unwrap_or_else(|| panic!("{}: not in {CHANNELS} (the freezer adds it)", e.file));
        assert_eq!(
            line,
            format!("{} {values} {bvh}", e.file),
            "{}: channels or BVH text changed",
            e.file
        );
        checked.push(e.file);
    }
    assert!(checked.len() >= 3, "only {checked:?}");
    // And no line for a file that is not a frozen channel take.
    for l in text.lines() {
        let file = l.split(' ').next().unwrap_or_default();
        assert!(
            checked.iter().any(|c| c == file),
            "{CHANNELS}: {l:?} names no channel take"
        );
    }
}

/// Add the `channels.txt` lines of frozen channel takes that have none (the freezer's last
/// step).
fn add_channel_lines() {
    let path = dir().join(CHANNELS);
    let mut text = std::fs::read_to_string(&path).unwrap_or_default();
    for e in index() {
        if text
            .lines()
            .any(|l| l.split(' ').next() == Some(e.file.as_str()))
        {
            continue;
        }
        if let Some((values, bvh)) = channel_hashes(&e.file) {
            text.push_str(&format!("{} {values} {bvh}\n", e.file));
        }
    }
    std::fs::write(&path, text).unwrap();
}

/// One line of the index.
struct Entry {
    file: String,
    /// Of the file's bytes.
    bytes: String,
    /// Of what it decodes to.
    decoded: String,
    what: String,
}

/// Every line of the index.
fn index() -> Vec<Entry> {
    let text = std::fs::read_to_string(dir().join("index.txt")).unwrap_or_default();
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let mut parts = l.splitn(4, ' ');
            let mut next = || parts.next().unwrap_or_default().to_string();
            let (file, bytes, decoded, what) = (next(), next(), next(), next());
            assert!(
                bytes.len() == 32 && decoded.len() == 32,
                "index.txt: {l:?} is not <file> <hash> <hash> <what>"
            );
            Entry {
                file,
                bytes,
                decoded,
                what,
            }
        })
        .collect()
}

#[test]
fn every_frozen_bitstream_decodes_to_what_it_decoded_to_when_written() {
    scalar::in_child();
    for e in index() {
        let got = digest(&decode_file(&dir().join(&e.file)));
        assert_eq!(
            got, e.decoded,
            "{} ({}) no longer decodes as it did",
            e.file, e.what
        );
    }
}

/// The plain build of the hot loops (`MOCAP_SCALAR=1`) decodes every frozen file, whole and
/// by ranges, to the same pinned bits as the AVX2 build this process runs.
#[test]
fn the_plain_build_decodes_every_frozen_bitstream_to_the_same_bits() {
    if scalar::in_child() || !scalar::parent_runs_the_vector_build() {
        return;
    }
    scalar::rerun(&[
        "every_frozen_bitstream_decodes_to_what_it_decoded_to_when_written",
        "every_frozen_bitstream_reads_any_range_as_the_same_rows_of_the_whole",
    ]);
}

/// A frozen file is never rewritten, and none is left out of the index.
#[test]
fn every_frozen_file_is_indexed_and_unchanged() {
    let index = index();
    for e in &index {
        let bytes = std::fs::read(dir().join(&e.file)).unwrap();
        assert_eq!(
            short_hash(&bytes),
            e.bytes,
            "{} was rewritten: a format change is a new version and a new file, never a \
             rewrite (tests/frozen/README.md)",
            e.file
        );
    }
    for f in std::fs::read_dir(dir()).unwrap() {
        let name = f.unwrap().file_name().to_string_lossy().into_owned();
        if name.ends_with(".mcst") {
            assert!(
                index.iter().any(|e| e.file == name),
                "{name} is not in tests/frozen/index.txt"
            );
        }
    }
    // Bases and skeletons are named by their content: a changed one no longer has its name.
    for f in std::fs::read_dir(dir().join("bases")).unwrap() {
        let path = f.unwrap().path();
        let b = Basis::parse(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!(
            format!("{}.mcsb", b.id()),
            path.file_name().unwrap().to_string_lossy(),
            "a frozen basis changed"
        );
    }
    for f in std::fs::read_dir(dir().join("skeletons")).unwrap() {
        let path = f.unwrap().path();
        let r = codec::Skeleton::parse(&std::fs::read(&path).unwrap(), 10_000).unwrap();
        assert_eq!(
            format!("{}.mcsk", r.id()),
            path.file_name().unwrap().to_string_lossy(),
            "a frozen skeleton changed"
        );
    }
}

/// Every codec × every parameter version its decoder accepts (as the code says) has a
/// frozen bitstream of that version.
#[test]
fn every_version_every_decoder_accepts_is_frozen() {
    let mut have = std::collections::BTreeSet::new();
    for e in index() {
        let bytes = std::fs::read(dir().join(&e.file)).unwrap();
        let c = Container::parse(&bytes, &DecodeLimits::default()).unwrap();
        let id = c.header.codec;
        let version = if id.is_analog() {
            c.header.params.first().copied()
        } else {
            codec::codec(id).unwrap().version_of(&c.header.params)
        };
        have.insert((id, version.expect("a frozen file of no version")));
    }
    let mut want = Vec::new();
    for id in CodecId::ALL {
        for &v in codec::codec(id).unwrap().versions() {
            want.push((id, v));
        }
    }
    for id in CodecId::ANALOG {
        for v in codec::analog::VERSIONS {
            want.push((id, v));
        }
    }
    let missing: Vec<String> = want
        .iter()
        .filter(|w| !have.contains(w))
        .map(|(id, v)| format!("{id} version {v}"))
        .collect();
    assert!(
        missing.is_empty(),
        "no frozen bitstream of {missing:?}: freeze one (see the module doc)"
    );
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

/// What the skeletal files frozen now code (the index's description).
const DANCER: &str = "a dancer BVH take with triples on other branches and two joints near lock";

/// `m` with some joints' Euler triples moved to equivalent ones (the other branch, whole
/// turns), as exporters write them: the same rotations, other channel values.
fn on_other_branches(mut m: Motion) -> Motion {
    let sk = m.skeleton.as_mut().unwrap();
    let cc: usize = sk.joints.iter().map(|j| j.channels.len()).sum();
    let mut first = 0;
    let mut triples = Vec::new();
    for j in &sk.joints {
        let rot: Vec<usize> = (0..j.channels.len())
            .filter(|&c| j.channels[c].rotation_axis().is_some())
            .map(|c| first + c)
            .collect();
        if rot.len() == 3 {
            triples.push(rot);
        }
        first += j.channels.len();
    }
    for (n, t) in triples.iter().enumerate().step_by(3) {
        for (f, row) in sk.values.chunks_exact_mut(cc).enumerate() {
            let (a, b, c) = (row[t[0]], row[t[1]], row[t[2]]);
            if (f / 40 + n) % 2 == 0 {
                row[t[0]] = a + 180.0;
                row[t[1]] = 180.0 - b;
                row[t[2]] = c + 180.0 - 360.0 * (n / 3 % 3) as f64;
            }
        }
    }
    m
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
        let enc = codec::encode(
            &m,
            codec,
            bound,
            codec::EncodeOptions::with_basis(basis.as_ref()),
        )
        .unwrap();
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
    // The same codecs on a take with gaps (runs of missing samples on most markers): what
    // the gap masks and the codecs' gap filling must go on decoding to.
    let gappy = walker(120, 5, 60.0, 12, 0.6);
    assert!(
        gappy.positions().iter().any(|v| v.is_nan()),
        "the take has gaps"
    );
    for (codec, basis) in [
        (CodecId::Raw, None),
        (CodecId::Quant, None),
        (CodecId::Mdtt, None),
        (CodecId::LsdtClip, Some(dct.clone())),
        (CodecId::LsdtFrame, Some(dct.clone())),
        (CodecId::Spca, None),
    ] {
        let enc = codec::encode(
            &gappy,
            codec,
            bound,
            codec::EncodeOptions::with_basis(basis.as_ref()),
        )
        .unwrap();
        let c = enc.container;
        let version = match codec {
            CodecId::Raw | CodecId::Quant | CodecId::Mdtt => String::new(),
            _ => format!("-v{}", c.header.params[0]),
        };
        out.push((
            format!("{codec}{version}-gaps"),
            c,
            basis,
            format!("{codec} batch, {bound}, a take with gaps"),
        ));
    }
    // quant's parameters version 2 (rANS tables), which the encoder keeps where it codes
    // smaller.
    let enc = codec::encode(
        &m,
        CodecId::Quant,
        bound,
        codec::EncodeOptions::with_encoder(None, |i, t| {
            codec::quant::encode_version(i, t, Some(2))
        }),
    )
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

    // The codecs that keep a skeleton's channels, on a small BVH take whose Euler triples
    // are not all on the canonical branch (what rot and pga version 3 carry per chunk) and
    // two of whose joints sit near gimbal lock (what version 4 twists; version 3's files
    // were frozen from the plain dancer).
    let bvh = on_other_branches(mocapstore::motion::synthetic::dancer_near_lock(
        150, 60.0, 11,
    ));
    let rig = Arc::new(codec::Skeleton::new(bvh.skeleton.clone().unwrap().joints).unwrap());
    std::fs::create_dir_all(dir().join("skeletons")).unwrap();
    std::fs::write(
        dir().join("skeletons").join(format!("{}.mcsk", rig.id())),
        rig.bytes(),
    )
    .unwrap();
    let mut skeletal = Vec::new();
    for codec in [CodecId::BvhLossless, CodecId::Rot, CodecId::Pga] {
        let c = codec::encode(&bvh, codec, bound, codec::EncodeOptions::default())
            .unwrap()
            .container;
        let name = format!("{codec}-v{}", c.header.params[0]);
        skeletal.push((name, c, format!("{codec} batch, {bound}, {DANCER}")));
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
        let c = codec::encode(
            &bvh,
            CodecId::Pga,
            bound,
            codec::EncodeOptions::with_encoder(None, |input, t| {
                let (rig, sk) = input.skeleton.unwrap();
                Take::new(rig, sk, input)?.encode(t, &[directions], &[options])
            }),
        )
        .unwrap()
        .container;
        skeletal.push((
            format!("pga-v{}-{name}", c.header.params[0]),
            c,
            format!("pga batch {what}, {bound}, {DANCER}"),
        ));
    }

    // `spca` with its torso normalisation, segments and blends.
    let c = codec::encode(
        &two_behaviours(),
        CodecId::Spca,
        bound,
        codec::EncodeOptions::default(),
    )
    .unwrap()
    .container;
    out.push((
        format!("spca-v{}-torso", c.header.params[0]),
        c,
        None,
        "spca batch, max 1 mm, normalised by the torso, two segments blended".into(),
    ));

    let mut index = std::fs::read_to_string(dir().join("index.txt")).unwrap_or_else(|_| {
        "# file, BLAKE3 (first 32 hex) of its bytes, of the decoded frames as little-endian \
         f32, what it is\n"
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
        let bytes = c.to_bytes();
        std::fs::write(dir().join(&file), &bytes).unwrap();
        let decoded = codec::decode_all_with(&c, basis).unwrap();
        let (b, d) = (short_hash(&bytes), digest(&decoded));
        index.push_str(&format!("{file} {b} {d} {what}\n"));
        eprintln!("froze {file}");
    }
    // Variants last, and a file whose bytes another already holds is not frozen twice
    // (pga's default encoding is one of its variants).
    skeletal.rotate_left(3);
    for (name, c, what) in skeletal {
        let file = format!("{name}.mcst");
        let bytes = c.to_bytes();
        let same = format!(" {} ", short_hash(&bytes));
        if index
            .lines()
            .any(|l| l.starts_with(&format!("{file} ")) || l.contains(&same))
        {
            continue;
        }
        std::fs::write(dir().join(&file), &bytes).unwrap();
        let shared = codec::Shared {
            basis: None,
            rig: Some(rig.clone()),
        };
        let decoded = codec::decode_all_with(&c, shared).unwrap();
        let (b, d) = (short_hash(&bytes), digest(&decoded));
        index.push_str(&format!("{file} {b} {d} {what}\n"));
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
        let bytes = c.to_bytes();
        std::fs::write(dir().join(&file), &bytes).unwrap();
        let what = format!(
            "{}, 8 channels (force plate, EMG) × 600 rows",
            c.header.codec
        );
        let (b, d) = (short_hash(&bytes), digest(&decode_analog(&c)));
        index.push_str(&format!("{file} {b} {d} {what}\n"));
        eprintln!("froze {file}");
    }
    std::fs::write(dir().join("index.txt"), index).unwrap();
    add_channel_lines();
}
