"""What the server's answers are, as Python values: a stored take's record ([`Take`]), a
range of its frames as a numpy array with its names and clock ([`Frames`]), and the
normalisation statistics of a selection's motion ([`MotionStats`])."""

from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, overload

import numpy as np
import numpy.typing as npt

F32Array = npt.NDArray[np.float32]


def nominal_rate(fps: float) -> float:
    """The rate a take's frame times are reckoned at, as the server reckons them: the
    nearest whole rate within 1e-4 (a frame time printed with rounding: BVH's 0.0333333 s
    is 30 fps), else ``fps``."""
    whole = round(fps)
    return float(whole) if whole >= 1 and abs(fps - whole) <= 1e-4 * fps else fps


@dataclass(frozen=True)
class Take:
    """A stored take: what it is, how it was coded, what that cost and what error it
    measured. ``raw`` is the server's record as it came, for fields this client does not
    name."""

    id: str
    name: str
    library: str
    tags: tuple[str, ...]
    fps: float
    frames: int
    points: int
    duration_s: float
    metres_per_unit: float
    codec: str
    max_bound_mm: float
    mean_bound_mm: float | None
    raw_bytes: int
    stored_bytes: int
    ratio: float
    max_mm: float
    mean_mm: float
    rms_mm: float
    created_at: int
    point_names: tuple[str, ...]
    source_format: str
    skeleton: str | None
    live: bool
    raw: dict[str, Any] = field(repr=False, compare=False)
    #: What the take is of: key → text or number.
    labels: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_json(cls, v: dict[str, Any]) -> Take:
        """A take from the server's JSON record."""
        meta = v.get("meta") or {}
        return cls(
            id=v["id"],
            name=v["name"],
            library=v.get("library", ""),
            tags=tuple(v.get("tags", ())),
            fps=float(v["fps"]),
            frames=int(v["frames"]),
            points=int(v["points"]),
            duration_s=float(v.get("duration_s", 0.0)),
            metres_per_unit=float(v["metres_per_unit"]),
            codec=v["codec"],
            max_bound_mm=float(v["max_bound_mm"]),
            mean_bound_mm=(
                float(v["mean_bound_mm"]) if v.get("mean_bound_mm") is not None else None
            ),
            raw_bytes=int(v["raw_bytes"]),
            stored_bytes=int(v["stored_bytes"]),
            ratio=float(v["ratio"]),
            max_mm=float(v["max_mm"]),
            mean_mm=float(v["mean_mm"]),
            rms_mm=float(v["rms_mm"]),
            created_at=int(v["created_at"]),
            point_names=tuple(meta.get("point_names", ())),
            source_format=v.get("source_format", ""),
            skeleton=v.get("skeleton"),
            live=bool(v.get("live", False)),
            raw=v,
            labels=dict(v.get("labels") or {}),
        )


@dataclass(frozen=True)
class Frames:
    """A range of a take's frames: ``data`` is ``(frames, points, 3)`` float32, NaN where a
    sample is missing, in ``metres_per_unit`` and at ``fps``. ``start`` is the take's frame
    the range starts at (the take's own frames, before any resampling).

    ``data`` is a read-only view of the answer's bytes (no copy); ``np.array(frames)`` or
    ``frames.data.copy()`` gives a writable one.

    ``frames["LeftHand"]`` is that point's ``(frames, 3)`` track; ``frames[10:20]`` and
    ``frames.between(1.0, 2.5)`` are ranges (by frame, by seconds from the range's start)."""

    data: F32Array
    point_names: tuple[str, ...]
    fps: float
    source_fps: float
    start: int
    metres_per_unit: float

    def __len__(self) -> int:
        return int(self.data.shape[0])

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> F32Array:
        a = self.data if dtype is None else self.data.astype(dtype)
        return a.copy() if copy else a

    @property
    def shape(self) -> tuple[int, ...]:
        """``(frames, points, 3)``."""
        return tuple(self.data.shape)

    @property
    def rate(self) -> float:
        """The rate times are reckoned at, as the server reckons them: ``fps``, or the whole
        rate a printed one was written for (a BVH's 0.0333333 s frames are 30 fps)."""
        return nominal_rate(self.fps)

    @property
    def times(self) -> npt.NDArray[np.float64]:
        """Seconds of each frame from the range's start (at [`rate`])."""
        return np.arange(len(self), dtype=np.float64) / self.rate

    def point(self, name: str) -> F32Array:
        """The ``(frames, 3)`` track of the point ``name``."""
        try:
            i = self.point_names.index(name)
        except ValueError:
            raise KeyError(f"no point {name!r} in these frames") from None
        return self.data[:, i, :]

    @overload
    def __getitem__(self, key: str) -> F32Array: ...

    @overload
    def __getitem__(self, key: slice) -> Frames: ...

    def __getitem__(self, key: str | slice) -> F32Array | Frames:
        if isinstance(key, str):
            return self.point(key)
        if not isinstance(key, slice):
            raise TypeError(
                "frames are indexed by a point's name or sliced by frame (f[10:20]); "
                "f.data[i] is frame i"
            )
        first, _, step = key.indices(len(self))
        if step != 1:
            raise ValueError("frames are sliced with a step of 1; resample with fps= instead")
        # ``start`` counts the take's own frames: the slice's first, at the take's rate.
        start = self.start + round(first * self.source_fps / self.fps) if self.fps else 0
        return replace(self, data=self.data[key], start=start)

    def between(self, t0: float, t1: float) -> Frames:
        """The frames at ``t0 <= t < t1`` seconds from the range's start."""
        drift = abs(self.fps / self.rate - 1)

        def at(t: float) -> int:
            # As the server counts: a time reckoned at either rate is at the same frame
            # (within a quarter frame).
            f = t * self.rate
            return int(np.ceil(f - min(1.5 * drift * abs(f) + 1e-9 * max(1.0, abs(f)), 0.25)))

        first = max(0, at(t0))
        end = max(first, at(t1))
        return self[first:end]

    def to_pandas(self) -> Any:
        """A long table: one row per frame and point (``frame``, ``time``, ``point``, ``x``,
        ``y``, ``z``); needs the ``pandas`` extra."""
        pd = importlib.import_module("pandas")  # an optional dependency (the extra)

        n, p, _ = self.data.shape
        flat = self.data.reshape(n * p, 3)
        return pd.DataFrame(
            {
                "frame": np.repeat(np.arange(n), p),
                "time": np.repeat(self.times, p),
                "point": np.tile(np.array(self.point_names, dtype=object), n),
                "x": flat[:, 0],
                "y": flat[:, 1],
                "z": flat[:, 2],
            }
        )


@dataclass(frozen=True)
class Columns:
    """Columns over a range of a take, each in its own unit: a C3D's analog channels
    (``Client.analog``) or its model outputs (``Client.outputs``: joint angles, forces,
    moments, powers, three columns ``name.x``, ``name.y``, ``name.z`` each).

    ``values`` is ``(samples, columns)`` float64, NaN where a value is missing, sampled at
    ``rate`` from ``t0`` seconds after the take's start; ``start`` is the take's frame the
    range starts at. ``columns["LHipAngles.x"]`` is that column."""

    values: npt.NDArray[np.float64]
    labels: tuple[str, ...]
    units: tuple[str, ...]
    rate: float
    t0: float
    start: int

    def __len__(self) -> int:
        return int(self.values.shape[0])

    def __getitem__(self, label: str) -> npt.NDArray[np.float64]:
        try:
            return self.values[:, self.labels.index(label)]
        except ValueError:
            raise KeyError(
                f"no column {label!r}; the columns are {', '.join(self.labels)}"
            ) from None

    def unit(self, label: str) -> str:
        """The unit of column ``label``."""
        if label not in self.labels:
            raise KeyError(f"no column {label!r}; the columns are {', '.join(self.labels)}")
        return self.units[self.labels.index(label)]


@dataclass(frozen=True, eq=False)
class StatsGroup:
    """The statistics of the takes of one layout (point names in order, in one unit):
    per point ``(points, 3)`` arrays of the positions' mean and standard deviation
    (population) and of their velocities' (units per second), ``present`` the frames each
    point is present in."""

    points: tuple[str, ...]
    metres_per_unit: float
    takes: int
    frames: int
    present: npt.NDArray[np.int64]
    mean: npt.NDArray[np.float64]
    std: npt.NDArray[np.float64]
    velocity_mean: npt.NDArray[np.float64]
    velocity_std: npt.NDArray[np.float64]

    @classmethod
    def from_json(cls, v: dict[str, Any]) -> StatsGroup:
        def per_point(key: str) -> npt.NDArray[np.float64]:
            return np.asarray(v[key], dtype=np.float64).reshape(-1, 3)

        return cls(
            points=tuple(v["points"]),
            metres_per_unit=float(v["metres_per_unit"]),
            takes=int(v["takes"]),
            frames=int(v["frames"]),
            present=np.asarray(v["present"], dtype=np.int64),
            mean=per_point("mean"),
            std=per_point("std"),
            velocity_mean=per_point("velocity_mean"),
            velocity_std=per_point("velocity_std"),
        )

    def scale(self, eps: float = 1e-8) -> npt.NDArray[np.float64]:
        """The standard deviations [`normalise`] divides by: 1 where a coordinate does not
        vary (below ``eps`` in the group's unit, or a point present in fewer than two
        frames), as scikit-learn's scalers do, so that it is not blown up."""
        flat = (self.std < eps) | (self.present[:, None] < 2)
        return np.where(flat, 1.0, self.std)

    def normalise(self, motion: npt.ArrayLike, eps: float = 1e-8) -> F32Array:
        """``motion`` ``(..., points, 3)`` of this layout, less the mean, over the standard
        deviation ([`scale`])."""
        a = np.asarray(motion, dtype=np.float32)
        return ((a - self.mean) / self.scale(eps)).astype(np.float32)

    def denormalise(self, motion: npt.ArrayLike, eps: float = 1e-8) -> F32Array:
        """The inverse of [`normalise`]."""
        a = np.asarray(motion, dtype=np.float32)
        return (a * self.scale(eps) + self.mean).astype(np.float32)


@dataclass(frozen=True, eq=False)
class MotionStats:
    """Normalisation statistics of a selection's motion (``GET /v1/motion-stats``), one
    [`StatsGroup`] per layout, most frames first; ``skipped`` the takes not counted in,
    each ``(id, name, reason)``; ``read`` how many takes the server read for this answer
    (it keeps the rest)."""

    by: str
    takes: int
    frames: int
    #: The rate, root and up axis asked for (``None``: each take's own).
    fps: float | None
    root: str
    up: str | None
    groups: tuple[StatsGroup, ...]
    skipped: tuple[tuple[str, str, str], ...]
    skipped_count: int
    read: int
    raw: dict[str, Any] = field(repr=False, compare=False)

    @classmethod
    def from_json(cls, v: dict[str, Any]) -> MotionStats:
        return cls(
            by=v["by"],
            takes=int(v["takes"]),
            frames=int(v["frames"]),
            fps=v["fps"],
            root=v["root"],
            up=v["up"],
            groups=tuple(StatsGroup.from_json(g) for g in v["groups"]),
            skipped=tuple((s["id"], s["name"], s["reason"]) for s in v["skipped"]),
            skipped_count=int(v["skipped_count"]),
            read=int(v["read"]),
            raw=v,
        )

    def group(self, points: Sequence[str]) -> StatsGroup:
        """The group of exactly these points, in this order (a take's ``point_names``, or an
        item's ``points``)."""
        want = tuple(points)
        found = [g for g in self.groups if g.points == want]
        if len(found) > 1:
            units = ", ".join(f"{g.metres_per_unit} m" for g in found)
            raise KeyError(
                f"these points come in {len(found)} units ({units}): ask the statistics "
                "(and the windows) with unit= to have one"
            )
        if found:
            return found[0]
        sizes = [len(g.points) for g in self.groups]
        raise KeyError(
            f"no group of these {len(want)} points ({', '.join(want[:3])}, ...); the groups "
            f"have {sizes} points"
        )

    def normalise(self, item: Mapping[str, Any], eps: float = 1e-6) -> F32Array:
        """A dataset item's ``motion`` normalised by its layout's group (found by the item's
        ``points``), 0 where its ``mask`` says a sample is missing."""
        out = self.group(item["points"]).normalise(item["motion"], eps)
        out[~np.asarray(item["mask"], dtype=bool)] = 0.0
        return out


@dataclass(frozen=True)
class Match:
    """One range found by a search: ``take`` (its id), its ``name`` and ``library``, the
    range in seconds (``t0 <= t < t1``) and in the take's own frames (``start:end``), and
    its ``score`` (lower is nearer; 0 is the same motion). ``missing_roles``: the query's
    body roles this take does not place (compared without them)."""

    take: str
    name: str
    library: str
    t0: float
    t1: float
    start: int
    end: int
    score: float
    missing_roles: tuple[str, ...] = ()

    @classmethod
    def from_json(cls, v: dict[str, Any]) -> Match:
        return cls(
            take=v["take"],
            name=v["name"],
            library=v["library"],
            t0=float(v["t0"]),
            t1=float(v["t1"]),
            start=int(v["start"]),
            end=int(v["end"]),
            score=float(v["score"]),
            missing_roles=tuple(v.get("missing_roles", ())),
        )

    def part(self) -> tuple[str, int, int]:
        """``(take, start, end)``: this range as [`Client.ranges`] reads it."""
        return (self.take, self.start, self.end)


@dataclass(frozen=True, eq=False)
class SearchResults(Sequence[Match]):
    """What a search found, best first (a sequence of [`Match`]); ``query`` the query as
    compared (``t0``, ``t1``, ``windows``, ``roles``), ``searched`` what was searched
    (``takes``, ``windows``, and the takes left out: ``unindexed``, ``live``,
    ``without_features``; ``index``, exact or approximate, and the takes ``scored``).
    ``client.ranges(results.parts())`` reads every range found in one request."""

    matches: tuple[Match, ...]
    query: dict[str, Any]
    searched: dict[str, Any]

    @classmethod
    def from_json(cls, v: dict[str, Any]) -> SearchResults:
        return cls(
            matches=tuple(Match.from_json(m) for m in v["results"]),
            query=dict(v["query"]),
            searched=dict(v["searched"]),
        )

    @overload
    def __getitem__(self, i: int) -> Match: ...
    @overload
    def __getitem__(self, i: slice) -> Sequence[Match]: ...
    def __getitem__(self, i: int | slice) -> Match | Sequence[Match]:
        return self.matches[i]

    def __len__(self) -> int:
        return len(self.matches)

    def parts(self) -> list[tuple[str, int, int]]:
        """Every range found as ``(take, start, end)``, for [`Client.ranges`]."""
        return [m.part() for m in self.matches]
