//! Golden bitstreams: the BLAKE3 of a few encodings is committed in `tests/golden/hashes.txt`,
//! so that any change to the container format, an entropy coder or an encoder's choices
//! shows up as a failing test and is made deliberately. After such a change, regenerate the
//! table with `MOCAPSTORE_BLESS=1 cargo test --test golden` (that value only) and say why in
//! the commit — and freeze the new format's bitstreams (`tests/frozen.rs`), so that takes
//! stored with the old one are still proven to decode.

use std::sync::Arc;

use mocapstore::codec::basis::Basis;
use mocapstore::codec::lsdt::spatial::dct_basis;
use mocapstore::codec::lsdt::{clip, frame};
use mocapstore::codec::mdtt::database::{train_bases, SetOptions};
use mocapstore::codec::{self, CodecId, ErrorBound};
use mocapstore::motion::synthetic::{walker, Rng};
use mocapstore::motion::units::Unit;
use mocapstore::motion::Motion;

#[path = "support/scalar.rs"]
mod scalar;

const TABLE: &str = "tests/golden/hashes.txt";

/// `m`'s frames with gaps filled (`filled`) as codec input.
fn input<'a>(m: &Motion, filled: &'a [f32], shared: Option<&'a Basis>) -> codec::Input<'a> {
    codec::Input {
        data: filled,
        valid: None,
        frames: m.frame_count(),
        points: m.point_count(),
        fps: m.fps,
        shared,
        skeleton: None,
        names: &[],
        torso: None,
    }
}

/// One golden encoding: its name, the BLAKE3 of its bytes, and for a whole take the BLAKE3 of
/// what it decodes to (the hashes are the table's; the decodes are compared between the AVX2
/// and the plain build).
struct Case {
    name: String,
    hash: String,
    decoded: Option<String>,
}

/// `m` encoded with `codec` at `bound`. The shared-basis codecs code with a basis made from
/// the take: the DCT (fixed, not trained, so the hash follows only the codec), or for
/// `mdtt-shared` two bases annealed from the take itself (deterministic: fixed seed).
fn case(name: &str, m: &Motion, codec: CodecId, bound: ErrorBound) -> Case {
    let basis = Arc::new(if codec == CodecId::MdttShared {
        let filled = codec::gaps::fill(m.positions(), m.point_count());
        train_bases(&[input(m, &filled, None)], 2, &SetOptions::default()).expect("trains")
    } else {
        dct_basis(m.point_count())
    });
    let enc = codec::encode(
        m,
        codec,
        bound,
        codec::EncodeOptions::with_basis(Some(&basis)),
    )
    .expect("encodes");
    let hash = blake3::hash(&enc.container.to_bytes());
    Case {
        name: format!("{name} {codec} {bound}"),
        hash: hash.to_hex()[..32].to_string(),
        decoded: Some(enc.decoded_digest.clone()),
    }
}

/// `points` markers moving as white noise, uniform in ±50 mm: nothing for a transform to
/// find.
fn noise(frames: usize, points: usize, fps: f64) -> Motion {
    let mut rng = Rng::new(7);
    let data = (0..frames * points * 3)
        .map(|_| (rng.unit() * 100.0 - 50.0) as f32)
        .collect();
    let names = (0..points).map(|i| format!("N{i}")).collect();
    Motion::new(fps, Unit::millimetres(), names, data, None).expect("consistent shape")
}

/// `points` markers standing still but for 0.05 mm of jitter.
fn still(frames: usize, points: usize, fps: f64) -> Motion {
    let mut rng = Rng::new(8);
    let at: Vec<f64> = (0..points * 3).map(|_| rng.unit() * 1000.0).collect();
    let data = (0..frames)
        .flat_map(|_| {
            at.iter()
                .map(|a| (a + 0.05 * rng.unit()) as f32)
                .collect::<Vec<_>>()
        })
        .collect();
    let names = (0..points).map(|i| format!("S{i}")).collect();
    Motion::new(fps, Unit::millimetres(), names, data, None).expect("consistent shape")
}

fn cases() -> Vec<Case> {
    let motions = [
        ("walker-240x8@120", walker(240, 8, 120.0, 1, 0.0)),
        ("walker-500x5@60-gaps", walker(500, 5, 60.0, 2, 0.3)),
    ];
    // Takes that send the rate searches down their rarer paths: white noise under a mean
    // bound tighter than the residual layer at the max can hold (the noise steps, MDTT's
    // residual fallbacks), and a still take under a mean bound (the step grows to its
    // ceiling).
    let searches = [
        (
            "noise-200x6@60",
            noise(200, 6, 60.0),
            ErrorBound::both(2.0, 0.3),
        ),
        ("still-300x6@60", still(300, 6, 60.0), ErrorBound::mean(3.0)),
    ];
    let encodings = [
        (CodecId::Raw, ErrorBound::max(1.0)),
        (CodecId::Quant, ErrorBound::max(1.0)),
        (CodecId::Quant, ErrorBound::mean(3.0)),
        (CodecId::Mdtt, ErrorBound::max(1.0)),
        (CodecId::Mdtt, ErrorBound::mean(3.0)),
        (CodecId::LsdtClip, ErrorBound::max(1.0)),
        (CodecId::LsdtClip, ErrorBound::mean(3.0)),
        (CodecId::LsdtFrame, ErrorBound::max(1.0)),
        (CodecId::LsdtFrame, ErrorBound::mean(3.0)),
        (CodecId::MdttShared, ErrorBound::max(1.0)),
        (CodecId::MdttShared, ErrorBound::mean(3.0)),
        (CodecId::Spca, ErrorBound::max(1.0)),
        (CodecId::Spca, ErrorBound::mean(3.0)),
    ];
    let mut out = Vec::new();
    for (name, m, bound) in &searches {
        for codec in [
            CodecId::Mdtt,
            CodecId::MdttShared,
            CodecId::LsdtClip,
            CodecId::LsdtFrame,
            CodecId::Spca,
        ] {
            out.push(case(name, m, codec, *bound));
        }
    }
    for (name, m) in &motions {
        for (codec, bound) in encodings {
            out.push(case(name, m, codec, bound));
        }
        // lsdt-frame's adaptive stage, what live streams are coded with (one frame at a
        // time, stream parameters): their chunks are stored as they are.
        let p = frame::stream_params(0.5 / m.unit.to_mm(), m.fps);
        let mut e = frame::FrameEncoder::new(p, &dct_basis(m.point_count())).expect("basis");
        let mut h = blake3::Hasher::new();
        h.update(&p.to_bytes());
        let w = m.point_count() * 3;
        for f in m.positions().chunks_exact(w) {
            if let (_, Some(c)) = e.push(f, None) {
                h.update(&c.bytes);
            }
        }
        if let Some(c) = e.finish() {
            h.update(&c.bytes);
        }
        out.push(Case {
            name: format!("{name} lsdt-frame adaptive (stream) max 0.5 mm"),
            hash: h.finalize().to_hex()[..32].to_string(),
            decoded: None,
        });
        // lsdt-clip's adaptive stage, what live streams are coded with (clip by clip).
        let p = clip::stream_params(0.5 / m.unit.to_mm(), m.fps);
        let basis = dct_basis(m.point_count());
        let filled = codec::gaps::fill(m.positions(), m.point_count());
        let mut h = blake3::Hasher::new();
        h.update(&p.to_bytes());
        for c in clip::encode_fixed(&input(m, &filled, Some(&basis)), p).expect("encodes") {
            h.update(&c.bytes);
        }
        out.push(Case {
            name: format!("{name} lsdt-clip adaptive (stream) max 0.5 mm"),
            hash: h.finalize().to_hex()[..32].to_string(),
            decoded: None,
        });
    }
    // The skeleton codecs, on a BVH take: channel values as printed (bvh-lossless), and
    // rotations held to a bound on the FK positions (rot, pga).
    let bvh = mocapstore::motion::synthetic::dancer(300, 60.0, 3);
    for (codec, bound) in [
        (CodecId::BvhLossless, ErrorBound::max(1.0)),
        (CodecId::Rot, ErrorBound::max(1.0)),
        (CodecId::Rot, ErrorBound::mean(3.0)),
        (CodecId::Pga, ErrorBound::max(1.0)),
        (CodecId::Pga, ErrorBound::mean(3.0)),
    ] {
        let enc =
            codec::encode(&bvh, codec, bound, codec::EncodeOptions::default()).expect("encodes");
        let hash = blake3::hash(&enc.container.to_bytes());
        out.push(Case {
            name: format!("dancer-300@60 {codec} {bound}"),
            hash: hash.to_hex()[..32].to_string(),
            decoded: Some(enc.decoded_digest.clone()),
        });
    }
    out
}

#[test]
fn encodings_match_the_committed_hashes() {
    let got: String = cases()
        .iter()
        .map(|c| format!("{}  {}\n", c.hash, c.name))
        .collect();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(TABLE);
    // Only the explicit value re-blesses: `MOCAPSTORE_BLESS=0` (or any other value) checks.
    if std::env::var("MOCAPSTORE_BLESS").as_deref() == Ok("1") {
        std::fs::write(&path, &got).unwrap();
        return;
    }
    let want = std::fs::read_to_string(&path).unwrap_or_default();
    assert_eq!(
        got, want,
        "bitstreams changed; if deliberate, run MOCAPSTORE_BLESS=1 cargo test --test golden"
    );
}

/// What each golden encoding is, as bytes and as decoded frames.
fn printed(cases: &[Case]) -> String {
    cases
        .iter()
        .map(|c| {
            let decoded = c.decoded.as_deref().unwrap_or("-");
            format!("golden {} {decoded} {}\n", c.hash, c.name)
        })
        .collect()
}

/// The plain build of the hot loops (`MOCAP_SCALAR=1`) writes the same bytes for every golden
/// encoding and decodes each to the same bits as the AVX2 build this process runs.
#[test]
fn the_plain_build_encodes_and_decodes_the_golden_takes_to_the_same_bits() {
    const NAME: &str = "the_plain_build_encodes_and_decodes_the_golden_takes_to_the_same_bits";
    if scalar::in_child() {
        // On a line of its own: libtest prints the test's name before its output.
        print!("\n{}", printed(&cases()));
        return;
    }
    if !scalar::parent_runs_the_vector_build() {
        return;
    }
    let plain: String = scalar::rerun(&[NAME])
        .lines()
        .filter(|l| l.starts_with("golden "))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(plain, printed(&cases()));
}
