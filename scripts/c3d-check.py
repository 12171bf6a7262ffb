#!/usr/bin/env python3
"""Check a C3D file we wrote against the service's own JSON answer of the same take
(`frames?format=json`, same transforms), through two independent readers (py-c3d and
ezc3d): point labels, rate, frame count, positions within --tol (the answer's units) and
missing samples where the answer has none.

    c3d-check.py RETURNED.c3d ANSWER.json [--tol T]

Positions are compared in metres (--tol is metres): the file's POINT:UNITS against the
answer's metres_per_unit (a unit C3D has no name for is written in mm).

Prints one JSON line: {"ok": bool, "problems": [...], "readers": [...]}, exits 1 on a
problem. The readers are those of c3d-compare.py.
"""
import argparse
import importlib.util
import json
import os
import re
import sys

import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("c3d_compare", os.path.join(here, "c3d-compare.py"))
compare = importlib.util.module_from_spec(spec)
spec.loader.exec_module(compare)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("returned")
    ap.add_argument("answer")
    ap.add_argument("--tol", type=float, default=1e-6)
    a = ap.parse_args()
    ours = json.load(open(a.answer))
    names = ours["points"]
    frames = ours["frames"]
    want = np.full((len(frames), len(names), 3), np.nan)
    for f, row in enumerate(frames):
        for p, s in enumerate(row):
            if s is not None:
                want[f, p] = s
    present = ~np.isnan(want).any(axis=2)
    want = want * ours["metres_per_unit"]
    import c3d

    with open(a.returned, "rb") as h:
        units = c3d.Reader(h).get("POINT:UNITS").string_value.strip()
    per_unit = {"mm": 0.001, "cm": 0.01, "m": 1.0}.get(units)
    if per_unit is None:
        problems_units = [f"POINT:UNITS {units!r} is not mm, cm or m"]
        per_unit = 1.0
    else:
        problems_units = []
    problems, readers = list(problems_units), []
    for name, read in (("py-c3d", compare.pyc3d_read), ("ezc3d", compare.ezc3d_read)):
        try:
            r = read(a.returned)
        except Exception as e:  # noqa: BLE001 - a reader that fails is a problem to report
            problems.append(f"{name}: cannot read: {e}")
            continue
        readers.append(name)
        # Our names are the file's labels made unique: a repeat gets "_2", "_3"…, a blank
        # label "P<n>"; the C3D we write keeps the upload's labels as they were.
        def same(theirs, ours):
            if theirs == ours:
                return True
            if theirs == "":
                return re.fullmatch(r"P\d+", ours) is not None
            return re.fullmatch(re.escape(theirs) + r"_\d+", ours) is not None

        labels = r["point_labels"]
        if len(labels) != len(names) or not all(same(x, y) for x, y in zip(labels, names)):
            diff = [(i, x, y) for i, (x, y) in enumerate(zip(labels, names)) if not same(x, y)]
            problems.append(f"{name}: {len(r['point_labels'])} labels vs {len(names)}, first differing {diff[:3]}")
        if abs(r["point_rate"] - ours["fps"]) > 1e-3 * ours["fps"]:
            problems.append(f"{name}: rate {r['point_rate']} vs {ours['fps']}")
        xyz, valid = r["xyz"] * per_unit, r["valid"]
        if xyz.shape[0] != len(frames):
            problems.append(f"{name}: {xyz.shape[0]} frames vs {len(frames)}")
            continue
        if (valid != present).any():
            f, p = np.argwhere(valid != present)[0]
            problems.append(f"{name}: frame {f} point {p} present {valid[f, p]} vs {present[f, p]}")
        d = np.linalg.norm(np.where(present[..., None], xyz - want, 0.0), axis=2)
        if d.size and d.max() > a.tol:
            f, p = np.unravel_index(np.argmax(d), d.shape)
            problems.append(f"{name}: frame {f} point {p} off by {d.max()} > {a.tol}")
    print(json.dumps({"ok": not problems and len(readers) == 2, "problems": problems, "readers": readers}))
    sys.exit(0 if not problems else 1)


main()
