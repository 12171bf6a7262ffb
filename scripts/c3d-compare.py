#!/usr/bin/env python3
"""Compare a C3D file we wrote with the file it came from, through two independent
readers (py-c3d and ezc3d): point labels and values (within --point-tol, the file's
units), analog values (identical, or each channel within its --analog-tol in its unit),
analog labels, rates, scales, offsets and units, events, and every FORCE_PLATFORM
parameter.

    c3d-compare.py ORIGINAL RETURNED [--point-tol MM] [--analog-tol LABEL=V ...]
                   [--frames A:B]

--frames compares frames A..B (0-based, end exclusive) of ORIGINAL with all of RETURNED
(a range read). Prints one JSON line: {"ok": bool, "problems": [...], "readers": [...]},
and exits 1 when a problem was found. A reader that cannot open ORIGINAL is skipped (and
named): what it cannot read, we cannot be compared against.
"""
import argparse
import json
import sys
import warnings

import numpy as np

warnings.simplefilter("ignore")


def pyc3d_read(path):
    import c3d

    with open(path, "rb") as h:
        r = c3d.Reader(h)
        pts, ana = [], []
        for _, p, a in r.read_frames(copy=True):
            pts.append(p.copy())
            ana.append(np.asarray(a, dtype=float).copy())
        g = lambda name: r.get(name)
        used = r.analog_used

        def strings(name):
            p = g(name)
            if p is None:
                return []
            return [s.strip() for s in p.string_array] if p.dimensions and len(p.dimensions) > 1 else [p.string_value.strip()]

        def floats(name):
            p = g(name)
            if p is None or p.num_elements == 0:
                return []
            if p.bytes_per_element == 2:
                return [float(x) for x in np.atleast_1d(p.int16_array).ravel()]
            if not p.dimensions:
                return [float(p.float_value)]
            return [float(x) for x in np.atleast_1d(p.float_array).ravel()]

        def ints(name):
            p = g(name)
            if p is None or p.num_elements == 0:
                return []
            if not p.dimensions:
                return [int(p.int16_value)]
            return [int(x) for x in np.atleast_1d(p.int16_array).ravel()]

        P = np.array(pts) if pts else np.zeros((0, 0, 5))
        valid = P[:, :, 3] >= 0 if P.size else np.zeros((0, 0), bool)
        xyz = P[:, :, :3] if P.size else np.zeros((0, 0, 3))
        A = np.concatenate([a for a in ana], axis=1) if ana and used > 0 and ana[0].size else np.zeros((used, 0))
        fp = {}
        grp = r.get("FORCE_PLATFORM")
        if grp is not None:
            for name, p in grp.param_items():
                if p.bytes_per_element == 4:
                    v = [float(x) for x in np.atleast_1d(p.float_array if p.dimensions else p.float_value).ravel()]
                elif p.bytes_per_element == 2:
                    v = [int(x) for x in np.atleast_1d(p.int16_array if p.dimensions else p.int16_value).ravel()]
                else:
                    v = bytes(p.bytes).hex()
                fp[name] = json.dumps(v)
        return {
            "point_labels": [s.strip() for s in r.point_labels],
            "analog_labels": [s.strip() for s in r.analog_labels] if used else [],
            "point_rate": float(r.point_rate),
            "first_frame": int(r.first_frame),
            "analog_rate": float(r.analog_rate) if used else None,
            "xyz": xyz,
            "valid": valid,
            "analog": A,
            "scales": floats("ANALOG:SCALE")[:used],
            "offsets": ints("ANALOG:OFFSET")[:used],
            "units": strings("ANALOG:UNITS")[:used],
            "gen_scale": floats("ANALOG:GEN_SCALE")[:1],
            "events": events(strings, floats, g),
            "force_platform": fp,
        }


def events(strings, floats, g):
    p = g("EVENT:USED")
    n = 0 if p is None else int(p.int16_value)
    if n == 0:
        return []
    t = floats("EVENT:TIMES")
    c = strings("EVENT:CONTEXTS")
    l = strings("EVENT:LABELS")
    return [(c[i] if i < len(c) else "", l[i] if i < len(l) else "", round(t[2 * i] * 60 + t[2 * i + 1], 5)) for i in range(n)]


def ezc3d_read(path):
    import ezc3d

    c = ezc3d.c3d(path)
    P = c["parameters"]
    pts = c["data"]["points"]  # 4 × points × frames
    an = c["data"]["analogs"]  # 1 × channels × samples
    val = lambda g, n, d=None: P[g][n]["value"] if g in P and n in P[g] else d
    used = int(np.atleast_1d(val("ANALOG", "USED", [0]))[0]) if "ANALOG" in P else 0
    fp = {}
    if "FORCE_PLATFORM" in P:
        for k, v in P["FORCE_PLATFORM"].items():
            if isinstance(v, dict) and "value" in v:
                x = v["value"]
                fp[k] = json.dumps(x if isinstance(x, list) else np.asarray(x).tolist())
    ev = []
    if "EVENT" in P and int(np.atleast_1d(val("EVENT", "USED", [0]))[0]) > 0:
        n = int(np.atleast_1d(val("EVENT", "USED"))[0])
        t = np.asarray(val("EVENT", "TIMES")).reshape(-1, 2) if np.asarray(val("EVENT", "TIMES")).ndim == 1 else np.asarray(val("EVENT", "TIMES")).T
        cx = list(val("EVENT", "CONTEXTS", []))
        lb = list(val("EVENT", "LABELS", []))
        ev = [(cx[i].strip() if i < len(cx) else "", lb[i].strip() if i < len(lb) else "", round(float(t[i][0]) * 60 + float(t[i][1]), 5)) for i in range(n)]
    xyz = np.transpose(pts[:3], (2, 1, 0))
    return {
        "point_labels": [s.strip() for s in val("POINT", "LABELS", [])][: pts.shape[1]],
        "analog_labels": [s.strip() for s in val("ANALOG", "LABELS", [])][:used] if used else [],
        "point_rate": float(np.atleast_1d(val("POINT", "RATE"))[0]),
        "first_frame": int(c["header"]["points"]["first_frame"]),
        "analog_rate": float(np.atleast_1d(val("ANALOG", "RATE"))[0]) if used else None,
        "xyz": xyz,
        "valid": ~np.isnan(xyz).any(axis=2),
        "analog": an[0] if an.size else np.zeros((used, 0)),
        "scales": [float(x) for x in np.atleast_1d(val("ANALOG", "SCALE", []))][:used],
        "offsets": [int(x) for x in np.atleast_1d(val("ANALOG", "OFFSET", []))][:used],
        "units": [s.strip() for s in val("ANALOG", "UNITS", [])][:used],
        "gen_scale": [float(x) for x in np.atleast_1d(val("ANALOG", "GEN_SCALE", [1.0]))][:1],
        "events": ev,
        "force_platform": fp,
    }


def compare(a, b, args, reader, problems):
    say = lambda msg: problems.append(f"{reader}: {msg}")
    f0, f1 = args.frames or (0, a["xyz"].shape[0])
    if a["point_labels"] != b["point_labels"]:
        say(f"point labels differ: {a['point_labels'][:5]}… vs {b['point_labels'][:5]}…")
    # The first frame's number: where the events' trial times fall (a range starts later).
    if a["first_frame"] + f0 != b["first_frame"] and a["xyz"].size:
        say(f"first frame {a['first_frame'] + f0} vs {b['first_frame']}")
    if abs(a["point_rate"] - b["point_rate"]) > 1e-3 and a["xyz"].size:
        say(f"point rate {a['point_rate']} vs {b['point_rate']}")
    xa, xb = a["xyz"][f0:f1], b["xyz"]
    if a.get("skip_xyz"):
        pass
    elif xa.size == 0 and xb.size > 0:
        pass  # the reader reads no points in the original (nor its rate): nothing to compare
    elif xa.shape != xb.shape:
        say(f"point data shape {xa.shape} vs {xb.shape}")
    else:
        va, vb = a["valid"][f0:f1], b["valid"]
        if (va != vb).any():
            say(f"{int((va != vb).sum())} samples differ in being missing")
        both = va & vb
        if both.any():
            err = float(np.abs(xa[both] - xb[both]).max())
            if err > args.point_tol:
                say(f"point error {err} over {args.point_tol}")
    for k in ("analog_labels", "scales", "offsets", "units", "gen_scale", "events", "force_platform"):
        if a[k] != b[k] and not (k == "gen_scale" and np.allclose(a[k] or [1.0], b[k] or [1.0])):
            say(f"{k} differ: {str(a[k])[:200]} vs {str(b[k])[:200]}")
    if a["analog_rate"] != b["analog_rate"] and not (
        a["analog_rate"] and b["analog_rate"] and abs(a["analog_rate"] - b["analog_rate"]) < 1e-3
    ):
        say(f"analog rate {a['analog_rate']} vs {b['analog_rate']}")
    if a.get("skip_analog"):
        return
    A, B = a["analog"], b["analog"]
    if A.shape[0]:
        per = A.shape[1] // max(a["xyz"].shape[0], 1)
        A = A[:, f0 * per : f1 * per]
    if A.shape != B.shape:
        say(f"analog shape {A.shape} vs {B.shape}")
        return
    tol = dict(args.analog_tol or [])
    for c in range(A.shape[0]):
        label = a["analog_labels"][c] if c < len(a["analog_labels"]) else str(c)
        t = tol.get(label, tol.get("*", 0.0))
        d = np.abs(A[c] - B[c])
        same_nan = np.isnan(A[c]) == np.isnan(B[c])
        if not same_nan.all():
            say(f"analog {label}: NaN where the other has a number")
        worst = float(np.nanmax(d)) if d.size and not np.isnan(d).all() else 0.0
        if (t == 0.0 and worst != 0.0) or worst > t:
            say(f"analog {label}: error {worst} over {t}")


def tol_item(s):
    k, v = s.rsplit("=", 1)
    return (k, float(v))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("original")
    ap.add_argument("returned")
    ap.add_argument("--point-tol", type=float, default=1e-3)
    ap.add_argument("--analog-tol", type=tol_item, action="append")
    ap.add_argument("--frames", type=lambda s: tuple(int(x) for x in s.split(":")))
    args = ap.parse_args()
    problems, readers = [], []
    originals = {}
    for name, read in (("py-c3d", pyc3d_read), ("ezc3d", ezc3d_read)):
        try:
            originals[name] = read(args.original)
        except Exception as e:  # what a reader cannot open, we cannot be compared against
            readers.append(f"{name}: skipped ({str(e)[:80]})")
    marks = {
        "xyz": ("samples differ in being missing", "point error", "point data shape", "point rate"),
        "analog": ("analog shape", ": error", "NaN where", "analog rate"),
    }
    aspect = lambda p: next((k for k, m in marks.items() if any(x in p for x in m) and (k == "xyz") != (": analog " in p or "analog rate" in p or "analog shape" in p)), None)
    # Where the two readers disagree on the upload's samples there is no one truth: the
    # returned file must then agree with the upload under at least one of them.
    disagree = set()
    if len(originals) == 2:
        same = []
        compare(originals["py-c3d"], originals["ezc3d"], argparse.Namespace(frames=None, point_tol=1e-3, analog_tol=[("*", 1e-6)]), "originals", same)
        for p in same:
            k = aspect(p)
            if k and k not in disagree:
                disagree.add(k)
                readers.append(f"readers disagree on the original's {k}: {p[:120]}")
    per_reader = {}
    for name, read in (("py-c3d", pyc3d_read), ("ezc3d", ezc3d_read)):
        if name not in originals:
            continue
        try:
            b = read(args.returned)
        except Exception as e:
            problems.append(f"{name}: cannot read the returned file: {e}")
            continue
        readers.append(name)
        mine = []
        compare(originals[name], b, args, name, mine)
        per_reader[name] = mine
    for k in disagree:
        if any(not [p for p in mine if aspect(p) == k] for mine in per_reader.values()):
            for name in per_reader:
                per_reader[name] = [p for p in per_reader[name] if aspect(p) != k]
    for mine in per_reader.values():
        problems.extend(mine)
    print(json.dumps({"ok": not problems, "problems": problems, "readers": readers}))
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
