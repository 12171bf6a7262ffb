//! Run tests of this test binary again in a child process on the plain build of the codecs'
//! hot loops (`MOCAP_SCALAR=1`, `mocapstore::codec::simd`), so a test can compare what both
//! builds give.

use std::process::Command;

use mocapstore::codec::simd;

/// Set in the child, so a test knows it is the rerun.
const CHILD: &str = "MOCAP_TEST_SCALAR_CHILD";

/// Whether this process is a rerun on the plain build; it checks that it is.
pub fn in_child() -> bool {
    let child = std::env::var_os(CHILD).is_some();
    if child {
        assert_eq!(
            simd::path(),
            simd::Path::Scalar,
            "{} did not take",
            simd::ENV
        );
    }
    child
}

/// Run test `name` of this binary with `MOCAP_SCALAR=1`; it must pass. Its printed output.
pub fn rerun(name: &str) -> String {
    let out = Command::new(std::env::current_exe().expect("the test binary"))
        .args(["--exact", name, "--nocapture", "--test-threads=1"])
        .env(simd::ENV, "1")
        .env(CHILD, "1")
        .output()
        .expect("runs the test binary");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success() && stdout.contains("1 passed"),
        "{name} on the plain build:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// The parent's own path: AVX2 where the CPU has it and `MOCAP_SCALAR` is not set, so that
/// the rerun compares two builds, not one with itself.
pub fn parent_path_is_the_vector_one_where_it_can_be() {
    #[cfg(target_arch = "x86_64")]
    if std::env::var_os(simd::ENV).is_none() && std::is_x86_feature_detected!("avx2") {
        assert_eq!(simd::path(), simd::Path::Avx2);
    }
}
