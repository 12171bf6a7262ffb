"""A library as training data: fixed-length windows of every take at one rate
([`Windows`]), indexable and shuffleable, fetched by range (the server decodes only the
chunks a window lies in) on kept-alive connections, several at once, through a bounded
cache in memory and optionally on disk. Each window is an item that says where it comes
from (``{"motion", "mask", "take", "name", "start", "fps", "labels", "points"}``);
[`collate`] stacks items of different rigs.

A [`Windows`] holds the server's address, not a connection: each process (a DataLoader
worker after ``fork``) opens its own client at its first fetch, so none is shared.
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
import warnings
from collections import OrderedDict, deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from . import _protocol
from .client import Client
from .skeleton import ROTATIONS, rotations
from .types import Frames, MotionStats, Take, nominal_rate

F32Array = npt.NDArray[np.float32]

#: A window as a dataset item: ``motion`` ``(frames, points, 3)`` float32 with 0 where a
#: sample is missing, ``mask`` ``(frames, points)`` bool (True where present), ``take``
#: (its id), ``name``, ``start`` (seconds from the take's start), ``fps``, ``labels`` and
#: ``points`` (the names, or roles, of the points in order).
Item = dict[str, Any]

#: Every body role the server places, in its order: what ``roles=True`` windows hold.
ROLES: tuple[str, ...] = (
    "pelvis",
    "spine",
    "neck",
    "head",
    *(
        f"{side}_{part}"
        for part in ("clavicle", "shoulder", "elbow", "wrist", "hip", "knee", "ankle", "toe")
        for side in ("left", "right")
    ),
)

#: Takes one statistics request may name by id (the server's limit).
MAX_STATS_IDS = 20_000

#: The fractions of takes in each split, in order.
SPLITS: dict[str, float] = {"train": 0.8, "val": 0.1, "test": 0.1}


def split_of(take_id: str, seed: int, splits: Mapping[str, float] | None = None) -> str:
    """The split a take belongs to: fixed by its id and ``seed`` alone, so a take stays in
    its split as takes are added or removed, and no take is in two."""
    shares = dict(splits or SPLITS)
    total = sum(shares.values())
    if total <= 0 or any(v < 0 for v in shares.values()):
        raise ValueError(f"split fractions must be ≥ 0 and not all 0, got {shares}")
    h = hashlib.sha256(f"{seed}:{take_id}".encode()).digest()
    u = int.from_bytes(h[:8], "big") / 2**64 * total
    for name, share in shares.items():
        if u < share:
            return name
        u -= share
    return next(reversed(shares))


def collate(items: Sequence[Item]) -> Item:
    """Items stacked into one batch: ``motion`` ``(batch, frames, points, 3)`` and ``mask``
    ``(batch, frames, points)``, padded (0, mask False) to the most points among them when
    their rigs differ; ``points`` the names of each item (a list of tuples); the other fields
    as lists. Windows of ``roles=True`` share one layout and need no padding."""
    if not items:
        raise ValueError("collate of no items")
    frames = {it["motion"].shape[0] for it in items}
    if len(frames) != 1:
        raise ValueError(f"items of different lengths {sorted(frames)} cannot be stacked")
    width = max(it["motion"].shape[1] for it in items)
    motion = np.zeros((len(items), frames.pop(), width, 3), dtype=np.float32)
    mask = np.zeros(motion.shape[:3], dtype=bool)
    for k, it in enumerate(items):
        n = it["motion"].shape[1]
        motion[k, :, :n] = it["motion"]
        mask[k, :, :n] = it["mask"]
    out: Item = {"motion": motion, "mask": mask}
    for key in ("take", "name", "start", "fps", "labels", "points"):
        out[key] = [it[key] for it in items]
    if all("rotation" in it for it in items):
        joints = max(it["rotation"].shape[1] for it in items)
        k = items[0]["rotation"].shape[2]
        rot = np.zeros((len(items), motion.shape[1], joints, k), dtype=np.float32)
        for i, it in enumerate(items):
            rot[i, :, : it["rotation"].shape[1]] = it["rotation"]
        out["rotation"] = rot
        out["joints"] = [it["joints"] for it in items]
    return out


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
    (default: ``seconds``, no overlap), resampled to ``fps``; ``frames = round(seconds *
    fps)`` frames each. ``w[i]`` is an [`Item`]; ``array(i)``, ``many`` and ``batch`` give
    the bare ``(frames, points, 3)`` float32 arrays, NaN where missing.

    ``server``: a URL (default ``MOCAP_SERVER``) or a [`Client`], whose URL and token are
    used. The selection: ``library``, ``tag`` and ``labels`` (``{"content": "walk"}``) on
    the server, ``where`` (a test of each [`Take`], for any field it lists: ``lambda t:
    t.fps >= 100``) and ``split`` (``"train"``, ``"val"`` or ``"test"``: each take's split
    is fixed by its id and ``seed``, ``splits`` the fractions, [`SPLITS`] by default).
    A selection with no window is an error that says why.

    ``rotation="quat"|"6d"|"euler"`` adds each skeleton take's joint rotations to its
    items (``rotation`` ``(frames, joints, 4|6|3)``, ``joints`` their names; read from the
    take's channels over the same range, rate and transforms, one request per window; see
    [`mocapstore.skeleton.rotations`]); a take without a skeleton is then missing what is
    asked. ``points`` selects and orders points by name; a take without them is an error
    naming it, unless ``on_missing="skip"`` (then ``skipped`` lists each take left out and what it
    lacks). ``roles=True`` gives every take the same layout, one point per body role
    ([`ROLES`]: the centroid of the points the server places in it, missing where none),
    so windows of different rigs stack. Without either, windows have each take's own
    points ([`collate`] pads them). ``unit``, ``up`` and ``root`` are the server's
    transforms.

    Windows are fetched at most ``batch_size`` to a request (``GET /v1/ranges``, one request
    for windows of many takes; a batch smaller than ``concurrency * batch_size`` is split
    evenly among the ``concurrency`` requests sent at once), so that the server's decode, not
    the client's per-request work, sets the pace.

    ``cache_bytes`` bounds the windows kept in memory; with ``cache_dir`` they are also
    kept on disk (at most ``disk_bytes``) for the next epoch or process."""

    def __init__(
        self,
        server: str | Client | None = None,
        token: str | None = None,
        *,
        url: str | None = None,
        library: str | None = None,
        tag: str | None = None,
        labels: Mapping[str, str | int | float] | None = None,
        where: Callable[[Take], bool] | None = None,
        split: str | None = None,
        splits: Mapping[str, float] | None = None,
        seed: int = 0,
        seconds: float = 1.0,
        fps: float = 30.0,
        stride: float | None = None,
        points: Sequence[str] | None = None,
        roles: bool = False,
        rotation: Literal["quat", "6d", "euler"] | None = None,
        on_missing: Literal["raise", "skip"] = "raise",
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
        if on_missing not in ("raise", "skip"):
            raise ValueError(f"on_missing is 'raise' or 'skip', not {on_missing!r}")
        if points is not None and roles:
            raise ValueError("points= and roles=True choose the points two ways: pick one")
        if roles and root == "extract":
            raise ValueError(
                "roles=True gives body roles only, and root='extract' adds the root's path as "
                "a point: use root='in-place' with roles, or points= with root='extract'"
            )
        if url is not None:
            if server is not None:
                raise ValueError("give the server once: server= (or url=, its old name)")
            server = url
        if rotation is not None and rotation not in ROTATIONS:
            raise ValueError(f"rotation is one of {', '.join(ROTATIONS)}, not {rotation!r}")
        shares = dict(splits or SPLITS)
        if split is not None and split not in shares:
            raise ValueError(f"split {split!r} is none of {', '.join(shares)}")
        if isinstance(server, Client):
            url, token = server.url, server.token if token is None else token
        elif server is None or isinstance(server, str):
            url = server
        else:
            raise TypeError(
                f"Windows takes a server URL or a mocapstore.Client, not {type(server).__name__}"
            )
        self.url, self.token = url, token
        self.seconds, self.fps = seconds, fps
        self.stride = stride if stride is not None else seconds
        self.frames = max(1, round(seconds * fps))
        self.points = _protocol.names(points)
        self.roles = roles
        self.rotation = rotation
        self.unit, self.up, self.root = unit, up, root
        self.cache_bytes, self.disk_bytes = cache_bytes, disk_bytes
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        self.concurrency = max(1, concurrency)
        self.batch_size = max(1, batch_size)
        self._client: Client | None = None
        self._pid = 0
        self._stats: MotionStats | None = None
        self._memory: OrderedDict[int, F32Array] = OrderedDict()
        self._held = 0
        self._disk_written = 0
        self._lock = threading.Lock()
        self._client_lock = threading.Lock()
        #: Takes left out by ``on_missing="skip"``: (name, the points it lacks).
        self.skipped: list[tuple[str, tuple[str, ...]]] = []
        with Client(url, token) as c:
            listed = list(c.takes(library=library, tag=tag, labels=labels))
            chosen = [
                t
                for t in listed
                if (where is None or where(t))
                and (split is None or split_of(t.id, seed, shares) == split)
            ]
            if roles:
                # A take stored before bodies were derived gets its body at its first read.
                chosen = [t if t.raw.get("body") else c.take(t.id) for t in chosen]
        self.windows = self._index(chosen, on_missing)
        if not self.windows:
            raise ValueError(self._why_empty(listed, chosen, library, tag, labels, split))
        self._key = hashlib.sha256(
            repr((self.fps, self.frames, self.points, roles, unit, up, root)).encode()
        ).hexdigest()[:16]

    def _why_empty(
        self,
        listed: list[Take],
        chosen: list[Take],
        library: str | None,
        tag: str | None,
        labels: Mapping[str, Any] | None,
        split: str | None,
    ) -> str:
        """Why a selection gave no window, in the caller's terms."""
        asked = ", ".join(
            f"{k}={v!r}"
            for k, v in (("library", library), ("tag", tag), ("labels", labels))
            if v is not None
        )
        if not listed:
            return f"no window: no take matches {asked or 'the server (it holds none)'}"
        if not chosen:
            return (
                f"no window: {len(listed)} takes match {asked or 'the server'}, "
                f"none passes where= and split={split!r}"
            )
        if self.skipped and len(self.skipped) == len(chosen):
            return f"no window: every one of the {len(chosen)} takes lacks {self._asked()}"
        longest = max(t.frames / nominal_rate(t.fps) for t in chosen)
        return (
            f"no window: {len(chosen)} takes, none {self.seconds} s long "
            f"(the longest lasts {longest:.3f} s)"
        )

    def _asked(self) -> str:
        """What every take must have, in the caller's terms."""
        wants = []
        if self.points is not None:
            wants.append(f"points of {list(self.points)}")
        if self.rotation is not None:
            wants.append("a skeleton (for rotation=)")
        if self.roles:
            wants.append("body roles (for roles=True)")
        return " and ".join(wants)

    def _index(self, takes: list[Take], on_missing: str) -> list[Window]:
        out: list[Window] = []
        # The listed records name each take's points: no window asks for them again.
        self._records: dict[str, Take] = {}
        self._layouts: dict[str, list[list[int]]] = {}
        lacking: list[tuple[str, tuple[str, ...]]] = []
        for t in takes:
            self._records[t.id] = t
            missing = tuple(n for n in self.points or () if n not in t.point_names)
            if self.rotation is not None and t.skeleton is None:
                missing += ("a skeleton (for rotation=)",)
            if self.roles:
                self._layouts[t.id] = _role_layout(t)
                if not any(self._layouts[t.id]):
                    missing += ("body roles (its body.unplaced lists every one)",)
            if missing:
                lacking.append((t.name, missing))
                continue
            # Source frames a window spans: the fewest whose answer at ``fps`` has
            # ``frames`` frames (the server's grid, snapped as it snaps), and the step
            # between windows.
            span = math.ceil((self.frames - 1) * grid_step(t.fps, self.fps) - 1e-9) + 1
            step = max(1, round(self.stride * nominal_rate(t.fps)))
            for start in range(0, t.frames - span + 1, step):
                out.append(Window(t.id, t.name, start, start + span))
        if lacking and on_missing == "raise":
            shown = "; ".join(f"{n} lacks {', '.join(m)}" for n, m in lacking[:5])
            more = f" (and {len(lacking) - 5} more)" if len(lacking) > 5 else ""
            raise ValueError(
                f"{len(lacking)} of {len(takes)} takes lack {self._asked()}: "
                f"{shown}{more}; pass on_missing='skip' to leave them out"
            )
        self.skipped = lacking
        return out

    def statistics(self) -> MotionStats:
        """Normalisation statistics of these windows' takes (those with a window; every
        frame of each, at the windows' ``fps``, ``unit``, ``up`` and ``root``, of the
        ``points`` or ``roles`` the items hold), computed by the server in one pass and kept
        there: one group per layout. ``stats.normalise(item)`` normalises an item by its
        layout's group. For a split, pass the train split's to every split."""
        if self._stats is None:
            ids = list(dict.fromkeys(w.take for w in self.windows))
            if len(ids) > MAX_STATS_IDS:
                raise ValueError(
                    f"statistics of {len(ids)} takes by id: the server takes at most "
                    f"{MAX_STATS_IDS}; ask client.motion_stats(library=..., ...) for the "
                    "whole selection instead"
                )
            stats = self.client().motion_stats(
                ids=ids,
                points=self.points,
                by="roles" if self.roles else "points",
                fps=self.fps,
                root=self.root,
                up=self.up,
                unit=self.unit,
            )
            if stats.skipped_count:
                why = "; ".join(f"{name}: {reason}" for _, name, reason in stats.skipped[:3])
                warnings.warn(
                    f"the server left {stats.skipped_count} of the windows' takes out of the "
                    f"statistics ({why})",
                    stacklevel=2,
                )
            self._stats = stats
        return self._stats

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
                # The server answered when the windows were listed: a worker's first
                # request refused (a restart) is retried, not taken for no server at all.
                self._client.reached = True
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
            a = f.data[: self.frames]
            out.append(_by_roles(a, self._layouts[w.take]) if self.roles else np.array(a))
        return out

    def array(self, i: int) -> F32Array:
        """Window ``i`` as a bare ``(frames, points, 3)`` float32 array, NaN where missing
        (a writable array of its own)."""
        return self._get([i])[0]

    def item(self, i: int, motion: F32Array) -> Item:
        """Window ``i``'s [`Item`], its ``motion`` from the array ``motion``."""
        w = self.windows[i % len(self)]
        t = self._records[w.take]
        present = ~np.isnan(motion).any(axis=2)
        item: Item = {
            "motion": np.nan_to_num(motion, nan=0.0),
            "mask": present,
            "take": w.take,
            "name": w.name,
            "start": w.start / nominal_rate(t.fps),
            "fps": self.fps,
            "labels": dict(t.labels),
            "points": ROLES
            if self.roles
            else _protocol.with_heading(
                _protocol.frame_names(t, self.points, self.root), motion.shape[1]
            ),
        }
        if self.rotation is not None:
            item["joints"], item["rotation"] = self._rotations(w)
        return item

    def _rotations(self, w: Window) -> tuple[tuple[str, ...], F32Array]:
        """Window ``w``'s joint rotations ``(frames, joints, k)`` from the take's channels
        over the same range, rate and transforms (one request per window)."""
        ch = self.client().channels(
            w.take,
            start=w.start,
            end=w.end,
            fps=self.fps,
            unit=self.unit,
            up=self.up,
            root=self.root,
        )
        names, rot = rotations(ch, self.rotation or "quat")
        if len(rot) < self.frames:
            raise RuntimeError(f"{w.name}: {len(rot)} frames of channels, not {self.frames}")
        return names, rot[: self.frames].astype(np.float32)

    def __getitem__(self, i: int) -> Item:
        """Window ``i`` as an [`Item`]."""
        return self.item(i, self.array(i))

    def items(self, indices: Sequence[int]) -> list[Item]:
        """Windows ``indices`` as [`Item`]s, fetched as [`many`] fetches them."""
        return [self.item(i, a) for i, a in zip(indices, self.many(indices), strict=True)]

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

    def __iter__(self) -> Iterator[Item]:
        return self.iter()

    def iter(self, shuffle: bool = False, seed: int | None = None) -> Iterator[Item]:
        """Every window once as an [`Item`], fetched ``batch_size`` to a request, at most
        ``concurrency + 1`` requests ahead of the reader."""
        order = self.order(shuffle, seed)
        return (self.item(i, a) for i, a in zip(order, self._arrays(order), strict=True))

    def _arrays(self, order: list[int]) -> Iterator[F32Array]:
        """Windows ``order`` as arrays, ``batch_size`` to a request, at most ``concurrency +
        1`` requests ahead of the reader."""
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
        a = self.array(i)
        names = _protocol.with_heading(
            _protocol.frame_names(take, self.points, self.root), a.shape[1]
        )
        if self.roles:
            names = ROLES
        return Frames(a, names, self.fps, take.fps, w.start, 0.0).to_pandas()


def _role_layout(t: Take) -> list[list[int]]:
    """For each of [`ROLES`], the indices of take ``t``'s points the server places in it
    (its record's ``body.roles``), empty where none."""
    body = t.raw.get("body") or {}
    placed: Mapping[str, Sequence[str]] = body.get("roles") or {}
    index = {n: k for k, n in enumerate(t.point_names)}
    return [[index[n] for n in placed.get(r, ()) if n in index] for r in ROLES]


def _by_roles(a: F32Array, layout: list[list[int]]) -> F32Array:
    """``a`` ``(frames, points, 3)`` as one point per role: the centroid of the role's
    points (of those present in a frame), NaN where it has none."""
    out = np.full((a.shape[0], len(layout), 3), np.nan, dtype=np.float32)
    for r, idx in enumerate(layout):
        if idx:
            part = a[:, idx]
            present = np.logical_not(np.isnan(part).any(axis=2))
            total = np.where(present[..., None], part, 0.0).sum(axis=1)
            count = present.sum(axis=1)
            ok = count > 0
            out[ok, r] = total[ok] / count[ok, None]
    return out
