#![no_main]
use libfuzzer_sys::fuzz_target;
use mocapstore::codec::CodecId;

fuzz_target!(|data: &[u8]| mocapstore::fuzzing::decode(CodecId::Spca, data));
