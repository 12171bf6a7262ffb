"""A library as training data: fixed-length windows of every take at one rate
([`Windows`]), indexable and shuffleable, fetched by range (the server decodes only the
chunks a window lies in) on kept-alive connections, several at once, through a bounded
cache in memory and optionally on disk.

A [`Windows`] holds the server's address, not a connection: each process (a DataLoader
worker after ``fork``) opens its own client at its first fetch, so none is shared.
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
from collections import OrderedDict, deque
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _protocol
from .client import Client
from .types import Frames, Take

F32Array = npt.NDArray[np.float32]


def grid_step(source: float, to: float) -> float:
    """Source frames per output frame as the server resamples: ``source / to``, snapped to
    a fraction ``p / q`` (``q <= 16``) within 1e-4 (a rate printed to a few decimals)."""
    step = source / to
    for q in range(1, 17):
        n = round(step * q)
        if n >= 1 and abs(step - n / q) <= 1e-4 * step:
            return n / q
    return step


@dataclass(frozen=True)
class Window:
    """Where a window lies: its take and its first frame (the take's own frames)."""

    take: str
    name: str
    start: int
    end: int


class Windows:
    """Every ``seconds``-long window of a selection's takes, ``stride`` seconds apart
    (default: ``seconds``, no overlap), resampled to ``fps``; each is ``(frames, points,
    3)`` float32 with ``frames = round(seconds * fps)``, NaN where missing. ``points``
    selects and orders points by name (every take must have them); ``unit``, ``up`` and
    ``root`` are the server's transforms. Takes shorter than a window give none. Without
    ``points``, windows have each take's own points: stack them (``batch``, a DataLoader's
    collate) only over takes of one marker set or skeleton.

    Windows are fetched at most ``batch_size`` to a request (``GET /v1/ranges``, one request
    for windows of many takes; a batch smaller than ``concurrency * batch_size`` is split
    evenly among the ``concurrency`` requests sent at once), so that the server's decode, not
    the client's per-request work, sets the pace.

    ``cache_bytes`` bounds the windows kept in memory; with ``cache_dir`` they are also
    kept on disk (at most ``disk_bytes``) for the next epoch or process."""

    def __init__(
        self,
        url: str | None = None,
        token: str | None = None,
        *,
        library: str | None = None,
        tag: str | None = None,
        seconds: float = 1.0,
        fps: float = 30.0,
        stride: float | None = None,
        points: Sequence[str] | None = None,
        unit: str | None = None,
        up: str | None = None,
        root: str | None = None,
        cache_bytes: int = 256 << 20,
        cache_dir: str | os.PathLike[str] | None = None,
        disk_bytes: int = 4 << 30,
        concurrency: int = 4,
        batch_size: int = 64,
    ) -> None:
        if seconds <= 0 or fps <= 0 or (stride is not None and stride <= 0):
            raise ValueError("seconds, fps and stride must be positive")
        self.url, self.token = url, token
        self.seconds, self.fps = seconds, fps
        self.stride = stride if stride is not None else seconds
        self.frames = max(1, round(seconds * fps))
        self.points = _protocol.names(points)
        self.unit, self.up, self.root = unit, up, root
        self.cache_bytes, self.disk_bytes = cache_bytes, disk_bytes
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        self.concurrency = max(1, concurrency)
        self.batch_size = max(1, batch_size)
        self._client: Client | None = None
        self._pid = 0
        self._memory: OrderedDict[int, F32Array] = OrderedDict()
        self._held = 0
        self._disk_written = 0
        self._lock = threading.Lock()
        self._client_lock = threading.Lock()
        with Client(url, token) as c:
            self.windows = self._index(c.takes(library=library, tag=tag))
        self._key = hashlib.sha256(
            repr((self.fps, self.frames, self.points, unit, up, root)).encode()
        ).hexdigest()[:16]

    def _index(self, takes: Iterator[Take]) -> list[Window]:
        out: list[Window] = []
        # The listed records name each take's points: no window asks for them again.
        self._records: dict[str, Take] = {}
        for t in takes:
            self._records[t.id] = t
            if self.points is not None and not set(self.points) <= set(t.point_names):
                continue
            # Source frames a window spans: the fewest whose answer at ``fps`` has
            # ``frames`` frames (the server's grid, snapped as it snaps), and the step
            # between windows.
            span = math.ceil((self.frames - 1) * grid_step(t.fps, self.fps) - 1e-9) + 1
            step = max(1, round(self.stride * t.fps))
            for start in range(0, t.frames - span + 1, step):
                out.append(Window(t.id, t.name, start, start + span))
        return out

    def __len__(self) -> int:
        return len(self.windows)

    def __getstate__(self) -> dict[str, Any]:
        # What a worker process gets: the index and settings, no client, an empty cache.
        state = self.__dict__.copy()
        state.update(
            _client=None, _pid=0, _memory=OrderedDict(), _held=0, _lock=None, _client_lock=None
        )
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()
        self._client_lock = threading.Lock()

    def client(self) -> Client:
        """This process's client (made at its first use, and again after a fork)."""
        with self._client_lock:
            if self._client is None or self._pid != os.getpid():
                self._client = Client(self.url, self.token)
                self._pid = os.getpid()
            return self._client

    def _disk(self, i: int) -> Path | None:
        if self.cache_dir is None:
            return None
        w = self.windows[i]
        return self.cache_dir / self._key / f"{w.take}-{w.start}.npy"

    def _remember(self, i: int, a: F32Array) -> None:
        with self._lock:
            if i in self._memory:
                return
            self._memory[i] = a
            self._held += a.nbytes
            while self._held > self.cache_bytes and self._memory:
                _, old = self._memory.popitem(last=False)
                self._held -= old.nbytes

    def _fetch(self, indices: Sequence[int]) -> list[F32Array]:
        """Windows ``indices`` from the server, in one request per ``MAX_RANGES``; each an
        array of its own (not a view that would keep the whole answer alive)."""
        ws = [self.windows[i] for i in indices]
        got = self.client().ranges(
            [(self._records[w.take], w.start, w.end) for w in ws],
            fps=self.fps,
            points=self.points,
            unit=self.unit,
            up=self.up,
            root=self.root,
        )
        out: list[F32Array] = []
        for i, w, f in zip(indices, ws, got, strict=True):
            if len(f) < self.frames:
                raise RuntimeError(
                    f"window {i} of {w.name} gave {len(f)} frames, not {self.frames}"
                )
            out.append(np.array(f.data[: self.frames]))
        return out

    def __getitem__(self, i: int) -> F32Array:
        """Window ``i``: ``(frames, points, 3)`` float32 (a writable array of its own)."""
        return self._get([i])[0]

    def _get(self, indices: Sequence[int]) -> list[F32Array]:
        """Windows ``indices`` from the memory cache, the disk cache, or in one request for
        the rest; each a writable array of its own."""
        n = len(self)
        for i in indices:
            if not -n <= i < n:
                raise IndexError(i)
        idx = [i % n for i in indices]
        out: list[F32Array | None] = [None] * len(idx)
        with self._lock:
            for k, i in enumerate(idx):
                hit = self._memory.get(i)
                if hit is not None:
                    self._memory.move_to_end(i)
                    out[k] = hit.copy()
        missing: list[int] = []
        for k, i in enumerate(idx):
            if out[k] is not None:
                continue
            disk = self._disk(i)
            a: F32Array | None = None
            if disk is not None:
                try:
                    a = np.load(disk)
                except (FileNotFoundError, ValueError, OSError):
                    a = None  # not there, or removed by another worker meanwhile: a miss
            if a is None:
                missing.append(k)
                continue
            self._remember(i, a)
            out[k] = a.copy()
        if missing:
            # A window asked for twice in one batch is fetched once.
            wanted = list(dict.fromkeys(idx[k] for k in missing))
            fetched = dict(zip(wanted, self._fetch(wanted), strict=True))
            for i, a in fetched.items():
                disk = self._disk(i)
                if disk is not None:
                    self._store(disk, a)
                self._remember(i, a)
            for k in missing:
                out[k] = fetched[idx[k]].copy()
        got = [a for a in out if a is not None]
        if len(got) != len(out):
            raise RuntimeError(f"{len(out) - len(got)} of {len(out)} windows were not read")
        return got

    def _groups(self, indices: Sequence[int]) -> list[Sequence[int]]:
        """``indices`` in requests of at most ``batch_size``, and at least ``concurrency``
        requests when there are enough windows (the server decodes each request's parts in
        turn, its requests side by side)."""
        size = max(1, min(self.batch_size, math.ceil(len(indices) / self.concurrency)))
        return [indices[i : i + size] for i in range(0, len(indices), size)]

    def _store(self, path: Path, a: F32Array) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        # Named for this process and thread: two threads may store the same window at once.
        tmp = path.with_name(f"{path.name}.{os.getpid()}.{threading.get_ident()}.partial")
        with open(tmp, "wb") as out:
            np.save(out, a)
        tmp.replace(path)
        self._disk_written += a.nbytes
        # The folder is measured now and then (each file a window), not at every store.
        if self._disk_written < self.disk_bytes // 16:
            return
        self._disk_written = 0
        sized: list[tuple[float, int, Path]] = []
        for f in path.parent.glob("*.npy"):
            try:
                st = f.stat()
            except FileNotFoundError:
                continue  # another worker evicted it
            sized.append((st.st_mtime, st.st_size, f))
        total = sum(size for _, size, _ in sized)
        for _, size, old in sorted(sized):
            if total <= self.disk_bytes:
                break
            total -= size
            old.unlink(missing_ok=True)

    def many(self, indices: Sequence[int]) -> list[F32Array]:
        """Windows ``indices``, in their order, fetched ``batch_size`` to a request and
        ``concurrency`` requests at once."""
        groups = self._groups(indices)
        if len(groups) == 1:
            return self._get(groups[0])
        with ThreadPoolExecutor(self.concurrency) as pool:
            return [a for got in pool.map(self._get, groups) for a in got]

    def batch(self, indices: Sequence[int]) -> F32Array:
        """Windows ``indices`` stacked, ``(len, frames, points, 3)`` (see [`many`])."""
        return np.stack(self.many(indices))

    def order(self, shuffle: bool = False, seed: int | None = None) -> list[int]:
        """The windows' indices, in order or shuffled (``seed`` for the same order again)."""
        idx = list(range(len(self)))
        if shuffle:
            np.random.default_rng(seed).shuffle(idx)
        return idx

    def __iter__(self) -> Iterator[F32Array]:
        return self.iter()

    def iter(self, shuffle: bool = False, seed: int | None = None) -> Iterator[F32Array]:
        """Every window once, fetched ``batch_size`` to a request, at most ``concurrency +
        1`` requests ahead of the reader."""
        order = self.order(shuffle, seed)
        groups = [order[i : i + self.batch_size] for i in range(0, len(order), self.batch_size)]
        with ThreadPoolExecutor(self.concurrency) as pool:
            pending: deque[Future[list[F32Array]]] = deque()
            try:
                for g in groups:
                    pending.append(pool.submit(self._get, g))
                    if len(pending) > self.concurrency:
                        yield from pending.popleft().result()
                while pending:
                    yield from pending.popleft().result()
            finally:
                for f in pending:
                    f.cancel()

    def to_pandas(self, i: int) -> Any:
        """Window ``i`` as a long table (``frame``, ``time``, ``point``, ``x``, ``y``,
        ``z``); needs the ``pandas`` extra."""
        w = self.windows[i]
        take = self._records[w.take]
        names = _protocol.frame_names(take, self.points, self.root)
        return Frames(self[i], names, self.fps, take.fps, w.start, 0.0).to_pandas()
