"""A real server for the tests: the binary `cargo build` made (``MOCAPSTORE_BIN``, else
``target/debug/mocapstore`` of this repository), on port 0, over SQLite in a temporary
folder, and over Postgres too when ``MOCAP_TEST_PY_PG_URL`` names a database for it."""

from __future__ import annotations

import os
import re
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]

BACKENDS = ["sqlite"] + (["postgres"] if os.environ.get("MOCAP_TEST_PY_PG_URL") else [])


def _binary() -> str:
    b = os.environ.get("MOCAPSTORE_BIN") or str(REPO / "target" / "debug" / "mocapstore")
    if not Path(b).is_file():
        raise RuntimeError(f"no server binary at {b}: run `cargo build` first")
    return b


@pytest.fixture(scope="session", params=BACKENDS)
def server(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[str]:
    if request.param == "postgres":
        url = os.environ["MOCAP_TEST_PY_PG_URL"]
    else:
        url = f"sqlite://{tmp_path_factory.mktemp('store') / 'store.db'}"
    proc = subprocess.Popen(
        [_binary(), "serve", "--listen", "127.0.0.1:0", "--database-url", url],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "NO_COLOR": "1", "RUST_LOG": "info"},
    )
    assert proc.stdout is not None
    address = None
    for line in proc.stdout:
        plain = re.sub(r"\x1b\[[0-9;]*m", "", line)
        m = re.search(r"listening.*address=(\S+)", plain)
        if m:
            address = m.group(1)
            break
    if address is None:
        proc.kill()
        raise RuntimeError("the server did not start")
    # The server keeps logging: read it all, or a full pipe would stop it.
    threading.Thread(target=proc.stdout.read, daemon=True).start()
    try:
        yield f"http://{address}"
    finally:
        proc.terminate()
        proc.wait(timeout=30)


@pytest.fixture(scope="session")
def corpus() -> Path | None:
    root = Path(os.environ.get("MOCAP_CORPUS", REPO.parent / "shared" / "data"))
    return root if (root / "manifest.csv").is_file() else None
