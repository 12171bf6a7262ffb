#!/usr/bin/env python3
"""Forward kinematics of a BVH file, written from the format alone (numpy, vectorised over
frames), as an independent reference for the project's reader. Prints one JSON line:

  {"names": [...], "parents": [...], "frames": F, "frame_time": s,
   "positions": [[[x, y, z], ...], ...]}

positions[f][n] is point n's world position at output frame f, in file units. Points are
every joint AND every End Site, in file order; an End Site is named "<parent name>_End",
made unique by appending 2, 3, ... if that name is taken (by any joint of the file, or by an
earlier End Site). parents[n] is the index of n's parent (null for the root).

Semantics: a joint's channels compose left to right in the order listed (R = R_c0 · R_c1 ·
R_c2, each a right-handed rotation about the channel's axis, in degrees); world = parent
world · [R | t]. t is the joint's OFFSET, and a position channel REPLACES its component
(exporters such as Vicon and Bandai put position channels on every joint with values that
repeat the offset; replacing keeps bones rigid). Tabs, CRLF, names with spaces (the name is
the rest of the line after ROOT/JOINT) are read; the rows after Frame Time are all read,
whatever the Frames line says (a warning on stderr when they differ; a cut-off last row is
dropped with a warning, any other row of the wrong length is an error).

  scripts/bvh-fk.py FILE.bvh [--every N] [--frames A:B]

--frames A:B keeps rows A..B-1 (Python slice, either end may be omitted), --every N then
keeps every Nth of those.
"""
import argparse
import json
import sys

import numpy as np

AXES = {"x": 0, "y": 1, "z": 2}


def warn(msg):
    print(f"bvh-fk: {msg}", file=sys.stderr)


def parse_hierarchy(lines):
    """Returns (points, index of the line after MOTION). A point is a dict with name,
    parent, offset, channels (list of (kind, axis)), end (bool)."""
    points = []
    stack = []  # index of the open joint per brace level
    pending = None  # a point declared, its "{" not read yet
    i = 0
    while i < len(lines):
        raw = lines[i].strip()
        i += 1
        if not raw:
            continue
        parts = raw.split(None, 1)
        word, rest = parts[0], (parts[1] if len(parts) > 1 else "")
        word_u = word.upper()
        if word_u == "HIERARCHY":
            continue
        if word_u == "MOTION":
            return points, i
        if word_u in ("ROOT", "JOINT") or (word_u == "END" and rest.strip().upper().startswith("SITE")):
            name = rest.strip()
            opens = name.endswith("{")
            if opens:
                name = name[:-1].strip()
            parent = stack[-1] if stack else None
            if word_u == "ROOT" and stack:
                raise SystemExit(f"line {i}: ROOT inside a joint")
            if word_u == "JOINT" and not stack:
                raise SystemExit(f"line {i}: JOINT outside any ROOT")
            end = word_u == "END"
            points.append({"name": None if end else name, "parent": parent,
                           "offset": np.zeros(3), "channels": [], "end": end})
            pending = len(points) - 1
            if opens:
                stack.append(pending)
                pending = None
            continue
        # a line may carry braces next to other tokens ("{ OFFSET ...", "}")
        tokens = raw.replace("{", " { ").replace("}", " } ").split()
        j = 0
        while j < len(tokens):
            t = tokens[j]
            if t == "{":
                if pending is None:
                    raise SystemExit(f"line {i}: '{{' with no joint")
                stack.append(pending)
                pending = None
                j += 1
            elif t == "}":
                if not stack:
                    raise SystemExit(f"line {i}: unbalanced '}}'")
                stack.pop()
                j += 1
            elif t.upper() == "OFFSET":
                points[stack[-1]]["offset"] = np.array([float(v) for v in tokens[j + 1:j + 4]])
                j += 4
            elif t.upper() == "CHANNELS":
                n = int(tokens[j + 1])
                chans = []
                for c in tokens[j + 2:j + 2 + n]:
                    c = c.lower()
                    axis = AXES[c[0]]
                    kind = "pos" if c[1:].startswith("pos") else "rot"
                    if not c[1:].startswith(("pos", "rot")):
                        raise SystemExit(f"line {i}: unknown channel {c}")
                    chans.append((kind, axis))
                if len(chans) != n:
                    raise SystemExit(f"line {i}: CHANNELS {n} lists {len(chans)}")
                points[stack[-1]]["channels"] = chans
                j += 2 + n
            else:
                raise SystemExit(f"line {i}: unexpected {t!r}")
    raise SystemExit("no MOTION section")


def name_end_sites(points):
    taken = {p["name"] for p in points if not p["end"]}
    for p in points:
        if p["end"]:
            base = points[p["parent"]]["name"] + "_End"
            name, k = base, 2
            while name in taken:
                name, k = f"{base}{k}", k + 1
            p["name"] = name
            taken.add(name)


def parse_motion(lines, start, width):
    header_frames, frame_time = None, None
    rows = []
    for line in lines[start:]:
        s = line.strip()
        if not s:
            continue
        low = s.lower()
        if low.startswith("frames:"):
            header_frames = int(float(s.split(":", 1)[1]))
            continue
        if low.startswith("frame time:"):
            frame_time = float(s.split(":", 1)[1])
            continue
        rows.append(s)
    counts = [len(r.split()) for r in rows]
    if rows and counts[-1] != width and all(c == width for c in counts[:-1]):
        warn(f"last motion row has {counts[-1]} of {width} values, dropped")
        rows, counts = rows[:-1], counts[:-1]
    bad = [k for k, c in enumerate(counts) if c != width]
    if bad:
        raise SystemExit(f"motion rows {bad[:5]} do not have {width} values")
    if width == 0:
        data = np.zeros((len(rows), 0))
    else:
        data = np.array(" ".join(rows).split(), dtype=np.float64).reshape(-1, width)
    if header_frames is not None and header_frames != len(data):
        warn(f"header says {header_frames} frames, {len(data)} rows read")
    return data, frame_time


def axis_rotation(axis, deg):
    """(F, 3, 3) right-handed rotations by deg degrees about axis 0/1/2."""
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    m = np.zeros((len(a), 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]  # the plane rotated: i -> j
    m[:, axis, axis] = 1.0
    m[:, i, i] = c
    m[:, j, j] = c
    m[:, i, j] = -s
    m[:, j, i] = s
    return m


def forward(points, data):
    frames = data.shape[0]
    world_r = [None] * len(points)
    world_t = [None] * len(points)
    col = 0
    out = np.zeros((frames, len(points), 3))
    for k, p in enumerate(points):
        t = np.tile(p["offset"], (frames, 1))
        r = None
        for kind, axis in p["channels"]:
            v = data[:, col]
            col += 1
            if kind == "pos":
                t[:, axis] = v
            else:
                m = axis_rotation(axis, v)
                r = m if r is None else r @ m
        if r is None:
            r = np.broadcast_to(np.eye(3), (frames, 3, 3))
        par = p["parent"]
        if par is None:
            world_r[k], world_t[k] = r, t
        else:
            pr = world_r[par]
            world_t[k] = world_t[par] + np.einsum("fij,fj->fi", pr, t)
            world_r[k] = pr @ r
        out[:, k] = world_t[k]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("file")
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--frames", default=None, help="A:B, a Python slice of the rows")
    args = ap.parse_args()
    with open(args.file, "rb") as fh:
        text = fh.read().decode("utf-8", errors="replace")
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    points, motion_at = parse_hierarchy(lines)
    if not points:
        raise SystemExit("no joints")
    name_end_sites(points)
    width = sum(len(p["channels"]) for p in points)
    data, frame_time = parse_motion(lines, motion_at, width)
    a, b = 0, None
    if args.frames:
        lo, _, hi = args.frames.partition(":")
        a = int(lo) if lo.strip() else 0
        b = int(hi) if hi.strip() else None
    data = data[a:b:max(1, args.every)]
    pos = forward(points, data)
    print(json.dumps({
        "names": [p["name"] for p in points],
        "parents": [p["parent"] for p in points],
        "frames": int(pos.shape[0]),
        "frame_time": frame_time,
        "positions": np.round(pos, 6).tolist(),
    }))


if __name__ == "__main__":
    main()
