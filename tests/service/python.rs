//! The Python client (`clients/python`, issue 36) against this build's server: its own
//! pytest suite (every method against a real server over SQLite, and over a Postgres
//! database of its own when `MOCAP_TEST_PG_URL` is set), `ruff` and `mypy --strict`.
//! Runs when `MOCAP_TEST_PYCLIENT` names the Python `scripts/pyclient` made (`.ci/run` sets
//! it); fails, never skips, when it is set and something is wrong.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn run(python: &Path, args: &[&str], envs: &[(&str, String)]) {
    let pkg = Path::new(env!("CARGO_MANIFEST_DIR")).join("clients/python");
    let out = Command::new(python)
        .args(args)
        .current_dir(&pkg)
        .envs(envs.iter().map(|(k, v)| (*k, v.as_str())))
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", python.display()));
    assert!(
        out.status.success(),
        "python {}:\n{}\n{}",
        args.join(" "),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!(
        "python {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .last()
            .unwrap_or("")
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn the_python_client_passes_its_tests_and_checks() {
    let Some(python) = std::env::var_os("MOCAP_TEST_PYCLIENT").map(PathBuf::from) else {
        eprintln!("MOCAP_TEST_PYCLIENT is not set: skipping the Python client (scripts/pyclient makes one)");
        return;
    };
    run(&python, &["-m", "ruff", "check", "."], &[]);
    run(&python, &["-m", "ruff", "format", "--check", "."], &[]);
    run(&python, &["-m", "mypy", "--strict", "src", "tests"], &[]);
    let pg = common::postgres().await;
    let mut envs = vec![(
        "MOCAPSTORE_BIN",
        env!("CARGO_BIN_EXE_mocapstore").to_string(),
    )];
    if let Some(pg) = &pg {
        // The store is opened (migrated) here; the server opens it again.
        envs.push(("MOCAP_TEST_PY_PG_URL", pg.url().to_string()));
    }
    run(
        &python,
        &["-m", "pytest", "-q", "-p", "no:cacheprovider"],
        &envs,
    );
    if let Some(pg) = pg {
        pg.finish().await;
    }
}
