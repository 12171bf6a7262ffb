#!/usr/bin/env python3
"""Evaluate a glTF the way a player does, with an independent reader (pygltflib): each
node's translation, rotation and scale from the animation at every key time of any of its
samplers (a channel keyed at other times interpolated as the specification says), composed
down the node tree. Prints one JSON line:

  {"nodes": [names], "frames": F, "times": [...], "positions": [[[x, y, z], ...], ...],
   "visible": [[bool, ...], ...], "extras": {...}}

positions[f][n] is node n's world position at key f; visible is false where a node's
(or an ancestor's) scale is zero.

  scripts/gltf-eval.py FILE.glb|FILE.gltf
"""
import json
import struct
import sys

import numpy as np
from pygltflib import GLTF2

COMPONENTS = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}


def accessor(g, blob, i):
    a = g.accessors[i]
    if a.componentType != 5126:
        raise SystemExit(f"accessor {i}: component type {a.componentType}, not float")
    v = g.bufferViews[a.bufferView]
    n = COMPONENTS[a.type]
    start = (v.byteOffset or 0) + (a.byteOffset or 0)
    data = struct.unpack_from(f"<{a.count * n}f", blob, start)
    return np.array(data, dtype=np.float64).reshape(a.count, n)


def quat_matrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def resample(keys, values, times, interpolation, rotation):
    """A channel's values at `times` (held before its first key and after its last):
    STEP holds, LINEAR lerps, or slerps a rotation the short way (glTF 2.0, Appendix C)."""
    if interpolation == "CUBICSPLINE":
        raise SystemExit("CUBICSPLINE samplers with different inputs are not evaluated")
    out = np.empty((len(times), values.shape[1]))
    for i, t in enumerate(times):
        k = np.searchsorted(keys, t, side="right") - 1
        if k < 0 or k >= len(keys) - 1:
            out[i] = values[0 if k < 0 else len(keys) - 1]
            continue
        s = (t - keys[k]) / (keys[k + 1] - keys[k])
        a, b = values[k], values[k + 1]
        if interpolation == "STEP":
            out[i] = a
        elif rotation:
            d = np.dot(a, b)
            if d < 0:
                b, d = -b, -d
            if d > 0.9995:
                q = a + (b - a) * s
            else:
                th = np.arccos(min(d, 1.0))
                q = (np.sin((1 - s) * th) * a + np.sin(s * th) * b) / np.sin(th)
            out[i] = q / np.linalg.norm(q)
        else:
            out[i] = a + (b - a) * s
    return out


def main():
    path = sys.argv[1]
    g = GLTF2().load(path)
    blob = g.binary_blob() if path.endswith(".glb") else g.get_data_from_buffer_uri(g.buffers[0].uri)
    nodes = g.nodes
    n = len(nodes)
    anim = g.animations[0] if g.animations else None
    # Every key time of the animation: samplers may key different times (assimp's do).
    times = (np.unique(np.concatenate([accessor(g, blob, smp.input)[:, 0] for smp in anim.samplers]))
             if anim else np.zeros(1))
    frames = len(times)
    trs = []
    for node in nodes:
        t = np.tile(np.array(node.translation or [0, 0, 0], dtype=np.float64), (frames, 1))
        r = np.tile(np.array(node.rotation or [0, 0, 0, 1], dtype=np.float64), (frames, 1))
        s = np.tile(np.array(node.scale or [1, 1, 1], dtype=np.float64), (frames, 1))
        trs.append([t, r, s])
    if anim:
        for ch in anim.channels:
            sampler = anim.samplers[ch.sampler]
            keys = accessor(g, blob, sampler.input)[:, 0]
            out = accessor(g, blob, sampler.output)
            if len(keys) != frames or np.any(np.abs(keys - times) > 1e-6):
                out = resample(keys, out, times, sampler.interpolation or "LINEAR",
                               ch.target.path == "rotation")
            k = {"translation": 0, "rotation": 1, "scale": 2}[ch.target.path]
            trs[ch.target.node][k] = out
    parent = [None] * n
    for i, node in enumerate(nodes):
        for c in node.children or []:
            parent[c] = i
    positions = np.zeros((frames, n, 3))
    visible = np.ones((frames, n), dtype=bool)
    for f in range(frames):
        world = [None] * n
        order = []
        seen = set()

        def visit(i):
            if i in seen:
                return
            if parent[i] is not None:
                visit(parent[i])
            seen.add(i)
            order.append(i)

        for i in range(n):
            visit(i)
        for i in order:
            t, r, s = trs[i][0][f], trs[i][1][f], trs[i][2][f]
            m = np.eye(4)
            m[:3, :3] = quat_matrix(r) @ np.diag(s)
            m[:3, 3] = t
            p = parent[i]
            world[i] = m if p is None else world[p] @ m
            visible[f, i] = bool(np.all(s != 0)) and (p is None or visible[f, p])
            positions[f, i] = world[i][:3, 3]
    extras = g.scenes[g.scene or 0].extras or {}
    print(json.dumps({
        "nodes": [node.name for node in nodes],
        "frames": frames,
        "times": times.tolist(),
        "positions": positions.tolist(),
        "visible": visible.tolist(),
        "extras": extras,
    }))


main()
