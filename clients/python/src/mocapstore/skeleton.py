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
        """The joints' names, in file order."""
        return tuple(j.name for j in self.joints)

    @property
    def parents(self) -> npt.NDArray[np.int64]:
        """Each joint's parent index (-1 for a root), in file order."""
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
    """A BVH (as the server writes it) as its skeleton and channel values. Joint names are
    the rest of their line (they may hold spaces); End Sites are named as the server names
    their points (``<parent>_End``, then ``_End2``… when a name is taken)."""
    head, sep, motion = text.decode("utf-8").partition("MOTION")
    if not sep:
        raise BvhError("no MOTION section")
    lines = [ln.strip() for ln in head.splitlines() if ln.strip()]
    if not lines or lines[0] != "HIERARCHY":
        raise BvhError("no HIERARCHY")
    joints: list[Joint] = []
    stack: list[int] = []
    pending: tuple[str, int, bool] | None = None

    def unique(name: str) -> str:
        taken = {j.name for j in joints}
        if name not in taken:
            return name
        n = 2
        while f"{name}{n}" in taken:
            n += 1
        return f"{name}{n}"

    for line in lines[1:]:
        word, _, rest = line.partition(" ")
        rest = rest.strip()
        if word in ("ROOT", "JOINT"):
            pending = (rest, stack[-1] if stack else -1, False)
        elif word == "End":
            parent = stack[-1]
            pending = (unique(f"{joints[parent].name}_End"), parent, True)
        elif word == "{":
            if pending is None:
                raise BvhError("a brace without a joint")
            joints.append(Joint(pending[0], pending[1], (0.0, 0.0, 0.0), (), pending[2]))
            stack.append(len(joints) - 1)
            pending = None
        elif word == "OFFSET":
            x, y, z = (float(v) for v in rest.split()[:3])
            j = joints[stack[-1]]
            joints[stack[-1]] = Joint(j.name, j.parent, (x, y, z), j.channels, j.end_site)
        elif word == "CHANNELS":
            n, *names = rest.split()
            if len(names) != int(n):
                raise BvhError(f"CHANNELS {n} names {len(names)}")
            j = joints[stack[-1]]
            joints[stack[-1]] = Joint(j.name, j.parent, j.offset, tuple(names), j.end_site)
        elif word == "}":
            stack.pop()
        else:
            raise BvhError(f"unexpected {line!r} in the hierarchy")
    skeleton = Skeleton(tuple(joints))
    rows = motion.strip().splitlines()
    frames = int(rows[0].split(":")[1])
    frame_time = float(rows[1].split(":")[1])
    width = len(skeleton.channel_names)
    body = " ".join(rows[2 : 2 + frames])
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


#: What [`rotations`] gives per joint: a unit quaternion (w, x, y, z), the first two
#: columns of the rotation matrix (Zhou et al. 2019, continuous for learning), or the
#: file's Euler angles in degrees in its channel order.
ROTATIONS = {"quat": 4, "6d": 6, "euler": 3}


def _axis_quaternions(axis: str, degrees: F64Array) -> F64Array:
    """``(n, 4)`` quaternions (w, x, y, z) of turns by ``degrees`` about ``axis``."""
    half = np.radians(degrees) / 2
    q = np.zeros((len(degrees), 4))
    q[:, 0] = np.cos(half)
    q[:, "XYZ".index(axis) + 1] = np.sin(half)
    return q


def _multiply(a: F64Array, b: F64Array) -> F64Array:
    """The Hamilton products ``a ⊗ b`` of ``(n, 4)`` quaternions (w, x, y, z)."""
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=1,
    )


def quaternion_matrices(q: F64Array) -> F64Array:
    """``(..., 3, 3)`` rotation matrices of unit quaternions ``(..., 4)`` (w, x, y, z)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def rotations(ch: Channels, kind: str = "quat") -> tuple[tuple[str, ...], F64Array]:
    """The local rotation of every joint with rotation channels, ``(frames, joints, k)``
    (``k`` from [`ROTATIONS`]), and those joints' names. A joint's rotation is its channels'
    turns composed in file order (BVH's ``Zrotation Xrotation Yrotation`` is ``Rz·Rx·Ry``),
    as the server's forward kinematics composes them. Quaternions are signed so that
    ``w ≥ 0``."""
    if kind not in ROTATIONS:
        raise ValueError(f"rotation is one of {', '.join(ROTATIONS)}, not {kind!r}")
    names: list[str] = []
    out: list[F64Array] = []
    at = 0
    frames = len(ch)
    for j in ch.skeleton.joints:
        cols = [
            (at + k, c[0].upper())
            for k, c in enumerate(j.channels)
            if c.lower().endswith("rotation")
        ]
        at += len(j.channels)
        if not cols:
            continue
        names.append(j.name)
        if kind == "euler":
            out.append(ch.values[:, [c for c, _ in cols]])
            continue
        q = np.tile([1.0, 0.0, 0.0, 0.0], (frames, 1))
        for c, axis in cols:
            q = _multiply(q, _axis_quaternions(axis, ch.values[:, c]))
        q *= np.where(q[:, :1] < 0, -1.0, 1.0)
        if kind == "quat":
            out.append(q)
        else:
            m = quaternion_matrices(q)
            out.append(np.concatenate([m[:, :, 0], m[:, :, 1]], axis=1))
    width = ROTATIONS[kind]
    stacked = np.stack(out, axis=1) if out else np.zeros((frames, 0, width))
    return tuple(names), stacked
