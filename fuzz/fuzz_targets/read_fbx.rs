#![no_main]
use libfuzzer_sys::fuzz_target;
use mocapstore::motion::formats::Format;

fuzz_target!(|data: &[u8]| mocapstore::fuzzing::read(Format::Fbx, data));
