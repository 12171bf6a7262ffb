"""The package as ``pip install ./clients/python`` builds it: a wheel with every module
and ``py.typed``, ``httpx`` and ``numpy`` its only runtime dependencies, the extras, and
the server's version."""

from __future__ import annotations

import re
import subprocess
import sys
import zipfile
from pathlib import Path

import mocapstore
from mocapstore import _version

PKG = Path(__file__).resolve().parents[1]
REPO = PKG.parents[1]


def test_the_wheel_holds_the_package_its_types_and_only_its_dependencies(
    tmp_path: Path,
) -> None:
    # The build backend comes from the pinned dev requirements (no download at test time).
    build = ["wheel", "--quiet", "--no-deps", "--no-build-isolation", "-w", str(tmp_path)]
    subprocess.run(
        [sys.executable, "-m", "pip", "--disable-pip-version-check", *build, str(PKG)],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("mocapstore-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {f"mocapstore/{p.name}" for p in (PKG / "src" / "mocapstore").glob("*.py")}
    assert modules | {"mocapstore/py.typed"} <= names
    assert not any(n.startswith("tests/") for n in names)
    (meta_name,) = [n for n in names if n.endswith(".dist-info/METADATA")]
    meta = zipfile.ZipFile(wheel).read(meta_name).decode()
    requires = re.findall(r"^Requires-Dist: (.+)$", meta, re.M)
    runtime = sorted(r.split(">")[0].split("=")[0] for r in requires if "extra ==" not in r)
    assert runtime == ["httpx", "numpy", "tqdm"]
    extras = re.findall(r"^Provides-Extra: (.+)$", meta, re.M)
    assert sorted(extras) == ["pandas", "torch"]
    assert f"Version: {_version.__version__}" in meta


def test_versioned_with_the_server() -> None:
    cargo = (REPO / "Cargo.toml").read_text()
    server = re.search(r'^version = "([^"]+)"', cargo, re.M)
    assert server is not None
    assert mocapstore.__version__ == _version.__version__ == server.group(1)
    project = (PKG / "pyproject.toml").read_text()
    assert f'version = "{server.group(1)}"' in project
