"""A skeleton take's animation as arrays: its hierarchy ([`Skeleton`]: names, parents,
offsets, channel orders) and its channel values ([`Channels`]), read from the BVH the server
writes (the take's channel values as its codec kept them; for ``bvh-lossless`` as
uploaded). ``Channels.to_bvh`` writes that BVH back byte for byte."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

F64Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Joint:
    """One joint: its parent's index (-1 for a root), its offset from the parent and its
    channels in file order (``Xposition`` … ``Zrotation``). An End Site is a joint without
    channels, named ``<parent>_End`` as the server names its point."""

    name: str
    parent: int
    offset: tuple[float, float, float]
    channels: tuple[str, ...]
    end_site: bool = False

    @property
    def rotation_order(self) -> str:
        """The axes of its rotation channels in order, e.g. ``"ZXY"`` (``""`` if none)."""
        return "".join(c[0].upper() for c in self.channels if c.lower().endswith("rotation"))


@dataclass(frozen=True)
class Skeleton:
    joints: tuple[Joint, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def parents(self) -> npt.NDArray[np.int64]:
        return np.array([j.parent for j in self.joints], dtype=np.int64)

    @property
    def offsets(self) -> F64Array:
        """``(joints, 3)``."""
        return np.array([j.offset for j in self.joints], dtype=np.float64).reshape(-1, 3)

    @property
    def channel_names(self) -> tuple[str, ...]:
        """``joint.channel`` for every channel, in the order of a frame's values."""
        return tuple(f"{j.name}.{c}" for j in self.joints for c in j.channels)

    def columns(self, joint: str) -> slice:
        """Where ``joint``'s channels lie in a frame's values."""
        at = 0
        for j in self.joints:
            if j.name == joint:
                return slice(at, at + len(j.channels))
            at += len(j.channels)
        raise KeyError(f"no joint {joint!r}")


@dataclass(frozen=True)
class Channels:
    """Channel values ``(frames, channels)`` of a skeleton take, in the skeleton's order,
    at ``fps``, from the take's frame ``start``."""

    skeleton: Skeleton
    values: F64Array
    fps: float
    start: int
    bvh: bytes = field(repr=False)

    def __len__(self) -> int:
        return int(self.values.shape[0])

    def joint(self, name: str) -> F64Array:
        """``(frames, k)``: the values of ``name``'s channels."""
        return self.values[:, self.skeleton.columns(name)]

    def to_bvh(self, path: str | Path) -> Path:
        """The BVH these channels were read from, as the server wrote it."""
        p = Path(path)
        p.write_bytes(self.bvh)
        return p


class BvhError(ValueError):
    """A BVH this module cannot read."""


def parse(text: bytes, start: int = 0) -> Channels:
    """A BVH (as the server writes it) as its skeleton and channel values."""
    head, sep, motion = text.decode("utf-8").partition("MOTION")
    if not sep:
        raise BvhError("no MOTION section")
    tokens = head.split()
    if not tokens or tokens[0] != "HIERARCHY":
        raise BvhError("no HIERARCHY")
    joints: list[Joint] = []
    stack: list[int] = []
    i = 1
    pending: tuple[str, int, bool] | None = None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    channels: tuple[str, ...] = ()
    while i < len(tokens):
        t = tokens[i]
        if t in ("ROOT", "JOINT"):
            pending = (tokens[i + 1], stack[-1] if stack else -1, False)
            i += 2
        elif t == "End":
            parent = stack[-1]
            pending = (f"{joints[parent].name}_End", parent, True)
            i += 2
        elif t == "{":
            if pending is None:
                raise BvhError("a brace without a joint")
            offset, channels = (0.0, 0.0, 0.0), ()
            joints.append(Joint(pending[0], pending[1], offset, channels, pending[2]))
            stack.append(len(joints) - 1)
            pending = None
            i += 1
        elif t == "OFFSET":
            x, y, z = (float(v) for v in tokens[i + 1 : i + 4])
            j = joints[stack[-1]]
            joints[stack[-1]] = Joint(j.name, j.parent, (x, y, z), j.channels, j.end_site)
            i += 4
        elif t == "CHANNELS":
            n = int(tokens[i + 1])
            j = joints[stack[-1]]
            names = tuple(tokens[i + 2 : i + 2 + n])
            joints[stack[-1]] = Joint(j.name, j.parent, j.offset, names, j.end_site)
            i += 2 + n
        elif t == "}":
            stack.pop()
            i += 1
        else:
            raise BvhError(f"unexpected {t!r} in the hierarchy")
    skeleton = Skeleton(tuple(joints))
    lines = motion.strip().splitlines()
    frames = int(lines[0].split(":")[1])
    frame_time = float(lines[1].split(":")[1])
    width = len(skeleton.channel_names)
    body = " ".join(lines[2 : 2 + frames])
    values = np.array(body.split(), dtype=np.float64) if frames else np.zeros(0)
    if values.size != frames * width:
        raise BvhError(f"{values.size} values for {frames} frames of {width} channels")
    return Channels(
        skeleton=skeleton,
        values=values.reshape(frames, width),
        fps=1.0 / frame_time if frame_time > 0 else 0.0,
        start=start,
        bvh=text,
    )
