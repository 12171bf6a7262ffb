#![no_main]
use libfuzzer_sys::fuzz_target;
use mocapstore::motion::formats::Format;

// GLB and .gltf alike: the reader tells them by the GLB magic.
fuzz_target!(|data: &[u8]| mocapstore::fuzzing::read(Format::Glb, data));
