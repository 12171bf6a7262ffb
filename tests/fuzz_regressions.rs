//! Every input that ever crashed a fuzz target (`scripts/fuzz` copies them to
//! `tests/fuzz-regressions/<target>/`) runs here, through the same code the target runs
//! (`mocapstore::fuzzing`): it must now come back as an error or a value, never a panic.

use std::path::Path;

use mocapstore::codec::CodecId;
use mocapstore::fuzzing;
use mocapstore::motion::formats::Format;

/// What each fuzz target runs.
fn run(target: &str, data: &[u8]) {
    match target {
        "read_bvh" => fuzzing::read(Format::Bvh, data),
        "read_c3d" => fuzzing::read(Format::C3d, data),
        "read_trc" => fuzzing::read(Format::Trc, data),
        "read_json" => fuzzing::read(Format::Json, data),
        "read_npy" => fuzzing::read(Format::Npy, data),
        "read_fbx" => fuzzing::read(Format::Fbx, data),
        "read_gltf" => fuzzing::read(Format::Glb, data),
        "decode_raw" => fuzzing::decode(CodecId::Raw, data),
        "decode_quant" => fuzzing::decode(CodecId::Quant, data),
        "decode_mdtt" => fuzzing::decode(CodecId::Mdtt, data),
        "decode_mdtt_shared" => fuzzing::decode(CodecId::MdttShared, data),
        "decode_lsdt_clip" => fuzzing::decode(CodecId::LsdtClip, data),
        "decode_lsdt_frame" => fuzzing::decode(CodecId::LsdtFrame, data),
        "decode_spca" => fuzzing::decode(CodecId::Spca, data),
        "decode_rot" => fuzzing::decode_skeletal(CodecId::Rot, data),
        "decode_pga" => fuzzing::decode_skeletal(CodecId::Pga, data),
        "decode_bvh_lossless" => fuzzing::decode_skeletal(CodecId::BvhLossless, data),
        "decode_analog" => fuzzing::decode_analog(data),
        "c3d_parameters" => fuzzing::c3d_parameters(data),
        "container" => fuzzing::container(data),
        "requests" => fuzzing::requests(data),
        other => panic!("no fuzz target {other}: add it here and to fuzz/"),
    }
}

#[test]
fn every_fuzz_target_is_known_here() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/fuzz_targets");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().replace(".rs", "");
        run(&name, b"");
        n += 1;
    }
    assert_eq!(n, 21);
}

#[test]
fn inputs_that_once_crashed_a_target_do_not_any_more() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz-regressions");
    let mut count = 0;
    for target in std::fs::read_dir(&root).unwrap() {
        let target = target.unwrap();
        if !target.file_type().unwrap().is_dir() {
            continue;
        }
        let name = target.file_name().to_string_lossy().into_owned();
        for input in std::fs::read_dir(target.path()).unwrap() {
            let path = input.unwrap().path();
            let data = std::fs::read(&path).unwrap();
            let outcome = std::panic::catch_unwind(|| run(&name, &data));
            assert!(outcome.is_ok(), "{} panics", path.display());
            count += 1;
        }
    }
    println!("{count} inputs that once crashed a fuzz target");
}
