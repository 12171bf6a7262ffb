"""The README's worked example runs as written: a linear classifier of the Bandai takes'
actions, trained on windows of the train split and scored on the validation split."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
REPO = Path(__file__).resolve().parents[3]


def example(tag: str) -> str:
    """The ```python block after ``<!-- example: TAG -->`` in the README."""
    text = README.read_text()
    m = re.search(rf"<!-- example: {tag} -->\s*```python\n(.*?)```", text, re.S)
    assert m, f"no example {tag!r} in {README}"
    return m.group(1)


def test_the_training_example_runs(server: str, corpus: Path | None) -> None:
    if corpus is None or corpus.resolve() != (REPO.parent / "shared" / "data").resolve():
        pytest.skip("the example reads ../shared/data from the repository's root")
    done = subprocess.run(
        [sys.executable, "-c", example("train")],
        cwd=REPO,
        env={**os.environ, "MOCAP_SERVER": server},
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr
    print(done.stdout)
    m = re.search(r"(\d+) actions, (\d+) train windows, val accuracy ([0-9.]+)", done.stdout)
    assert m, done.stdout
    actions, windows, accuracy = int(m.group(1)), int(m.group(2)), float(m.group(3))
    # Far better than guessing: the labels came through the split and the windows.
    assert actions >= 5 and windows > 100 and accuracy > 2 / actions, done.stdout
