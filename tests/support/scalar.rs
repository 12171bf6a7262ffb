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

/// Run tests `names` of this binary with `MOCAP_SCALAR=1`; each must pass (each calls
/// [`in_child`], which checks the switch took). Their printed output.
pub fn rerun(names: &[&str]) -> String {
    let out = Command::new(std::env::current_exe().expect("the test binary"))
        .args(names)
        .args(["--exact", "--nocapture", "--test-threads=1"])
        .env(simd::ENV, "1")
        .env(CHILD, "1")
        .output()
        .expect("runs the test binary");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let passed = format!("test result: ok. {} passed", names.len());
    assert!(
        out.status.success() && stdout.contains(&passed),
        "{names:?} on the plain build:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// Whether this process runs the AVX2 build, so that a rerun compares two builds; where it
/// cannot (no AVX2, or `MOCAP_SCALAR` set for the whole run), says so.
pub fn parent_runs_the_vector_build() -> bool {
    let vector = simd::path() == simd::Path::Avx2;
    if !vector {
        println!(
            "not compared: this process runs the plain build too (no AVX2, or {} set)",
            simd::ENV
        );
    }
    #[cfg(target_arch = "x86_64")]
    if std::env::var_os(simd::ENV).is_none() && std::is_x86_feature_detected!("avx2") {
        assert!(
            vector,
            "AVX2 is there and not switched off, yet the plain build runs"
        );
    }
    vector
}
