"""A library as windows: the right count and shape, each window the range the server
gives, every window once per epoch in order or shuffled, the cache in memory and on disk,
and two worker processes (fork) that read every window once between them."""

from __future__ import annotations

import multiprocessing
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

import mocapstore
from mocapstore.data import Windows

from .test_client import NAMES, walker


@pytest.fixture(scope="module")
def lib(server: str) -> str:
    name = f"py-data-{uuid.uuid4().hex[:8]}"
    with mocapstore.Client(server) as c:
        for frames in (150, 95, 40):  # 2.5 s, 1.6 s, 0.67 s at 60 fps
            c.ingest(walker(frames, gaps=True), library=name, fps=60, point_names=NAMES)
    return name


def first_window_of(w: Windows, i: int) -> int:
    return w.windows[i].start


def test_windows_count_shape_and_content(server: str, lib: str) -> None:
    w = Windows(server, library=lib, seconds=0.5, fps=30, points=["rhand", "head"])
    # 15 frames at 30 fps span 29 source frames at 60; one every 30: 5 + 3 + 1.
    assert len(w) == 9 and w.frames == 15
    a = w[5]
    assert a.shape == (15, 2, 3) and a.dtype == np.float32
    win = w.windows[5]
    with mocapstore.Client(server) as c:
        f = c.frames(win.take, start=win.start, end=win.end, fps=30, points=["rhand", "head"])
    assert a.tobytes() == f.data[:15].tobytes()
    # The left hand's gap (frames 20..35 of each take) is NaN in the windows over it.
    full = Windows(server, library=lib, seconds=0.5, fps=60)
    assert np.isnan(full[0][20:35, 1]).all() and not np.isnan(full[0][:20]).any()
    with pytest.raises(IndexError):
        w[9]
    # The last window of a take ends at its last frame.
    last = w.windows[4]
    assert last.end == 149 and w[4].shape == (15, 2, 3)


def test_every_window_once_in_order_or_shuffled(server: str, lib: str, tmp_path: Path) -> None:
    w = Windows(server, library=lib, seconds=0.25, fps=60, cache_dir=tmp_path)
    ordered = [a.tobytes() for a in w]
    assert len(ordered) == len(w) > 0
    assert w.order(shuffle=True, seed=3) == w.order(shuffle=True, seed=3)
    shuffled = [a.tobytes() for a in w.iter(shuffle=True, seed=3)]
    assert sorted(shuffled) == sorted(ordered)
    # A second Windows reads the same windows from the disk cache.
    again = Windows(server, library=lib, seconds=0.25, fps=60, cache_dir=tmp_path)
    calls = 0
    original = again._fetch

    def counted(indices: Sequence[int]) -> list[npt.NDArray[np.float32]]:
        nonlocal calls
        calls += 1
        return original(indices)

    again._fetch = counted  # type: ignore[method-assign]
    assert [again[i].tobytes() for i in range(len(again))] == ordered
    assert calls == 0
    assert w.batch([0, 2]).shape == (2, w.frames, len(NAMES), 3)


def test_windows_come_many_to_a_request(server: str, lib: str, tmp_path: Path) -> None:
    w = Windows(server, library=lib, seconds=0.25, fps=60, batch_size=4, concurrency=2)
    one = [Windows(server, library=lib, seconds=0.25, fps=60)[i].tobytes() for i in range(len(w))]
    asked: list[int] = []
    original = w._fetch

    def counted(indices: Sequence[int]) -> list[npt.NDArray[np.float32]]:
        asked.append(len(indices))
        return original(indices)

    w._fetch = counted  # type: ignore[method-assign]
    order = w.order(shuffle=True, seed=5)
    assert [a.tobytes() for a in w.iter(shuffle=True, seed=5)] == [one[i] for i in order]
    assert sum(asked) == len(w) and max(asked) == 4 and len(asked) == -(-len(w) // 4)
    # Read again: from memory, no request.
    asked.clear()
    assert [a.tobytes() for a in w.many(order)] == [one[i] for i in order]
    assert asked == []
    fresh = Windows(server, library=lib, seconds=0.25, fps=60, batch_size=64, concurrency=2)
    fresh._fetch = counted  # type: ignore[method-assign]
    # Split in two batches, [1, 0, 1] and [2, 3, 2], that share no window: which thread
    # finishes first cannot change what the other asks for.
    idx = [1, 0, 1, 2, 3, 2]
    assert [a.tobytes() for a in fresh.many(idx)] == [one[i] for i in idx]
    # A batch is split among the worker threads, a request each, a repeated window once.
    assert asked == [2, 2]
    # Repeats in one batch, split among threads, store the same window on disk at once.
    disk = Windows(server, library=lib, seconds=0.25, fps=60, concurrency=2, cache_dir=tmp_path)
    for _ in range(3):
        assert [a.tobytes() for a in disk.many(idx * 4)] == [one[i] for i in idx * 4]
        disk._memory.clear()


def _read(args: tuple[Windows, list[int]]) -> list[tuple[int, bytes]]:
    w, idx = args
    return [(i, w[i].tobytes()) for i in idx]


def test_two_worker_processes_read_every_window_once(server: str, lib: str) -> None:
    w = Windows(server, library=lib, seconds=0.25, fps=60)
    w[0]  # the parent's own client exists before the fork
    idx = w.order(shuffle=True, seed=1)
    halves = [(w, idx[0::2]), (w, idx[1::2])]
    with multiprocessing.get_context("fork").Pool(2) as pool:
        got = [x for part in pool.map(_read, halves) for x in part]
    assert sorted(i for i, _ in got) == list(range(len(w)))
    assert all(b == w[i].tobytes() for i, b in got)


def test_the_bench_runs(server: str, lib: str, capsys: pytest.CaptureFixture[str]) -> None:
    from mocapstore import bench

    bench.main([server, "--library", lib, "--windows", "5"])
    out = capsys.readouterr().out
    assert "windows/s" in out and "whole takes" in out and "client CPU" in out


def _read_batch(args: tuple[Any, list[int]]) -> list[Any]:
    ds, idx = args
    return list(ds.__getitems__(idx))


def test_the_torch_dataset_pickles_without_a_connection(
    server: str, lib: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # torch is not installed in CI (its wheel is over a gigabyte): a stand-in module with
    # the one function the dataset calls checks the wrapper itself.
    import pickle
    import sys
    import types

    fake = types.ModuleType("torch")
    fake.from_numpy = lambda a: ("tensor", a)  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "torch", fake)
    from mocapstore.torch import WindowDataset

    w = Windows(server, library=lib, seconds=0.25, fps=60)
    ds = WindowDataset(w)
    kind, a = ds[3]
    assert kind == "tensor" and a.tobytes() == w[3].tobytes() and len(ds) == len(w)
    copy = pickle.loads(pickle.dumps(ds))
    assert copy.windows._client is None and len(copy.windows._memory) == 0
    assert copy[3][1].tobytes() == a.tobytes()
    # What a DataLoader calls for a batch, when the dataset has it: one request.
    got = ds.__getitems__([3, 0, 3])
    assert [t[1].tobytes() for t in got] == [w[i].tobytes() for i in (3, 0, 3)]
    # As a DataLoader with 2 workers runs it: the dataset pickled to two forked processes,
    # each reading its batches of an epoch's shuffled order: every window once.
    order = w.order(shuffle=True, seed=2)
    batches = [order[i : i + 4] for i in range(0, len(order), 4)]
    with multiprocessing.get_context("fork").Pool(2) as pool:
        got_batches = pool.map(_read_batch, [(ds, b) for b in batches])
    seen = [i for b in batches for i in b]
    assert sorted(seen) == list(range(len(w)))
    flat = [t[1].tobytes() for b in got_batches for t in b]
    assert flat == [w[i].tobytes() for i in seen]
