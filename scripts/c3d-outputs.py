#!/usr/bin/env python3
"""The model outputs of a C3D file as py-c3d reads them: every point that POINT:ANGLES,
FORCES, MOMENTS or POWERS lists, its kind, the unit POINT:<KIND>_UNITS names, and its
values frame by frame (null where the residual marks a gap or a number is not finite).

    c3d-outputs.py FILE.c3d

Prints one JSON object: {"points": [every point label], "outputs": {label: {"kind": ...,
"unit": ..., "values": [[x, y, z] | null, ...]}}}. The labels are POINT:LABELS (and
LABELS2 …) as py-c3d gives them, stripped. A file py-c3d cannot open gives
{"unreadable": reason}: what it cannot read, we cannot be compared against.
"""
import json
import sys
import warnings

import numpy as np

warnings.simplefilter("ignore")

KINDS = [("angle", "ANGLES", "ANGLE_UNITS", "deg"), ("force", "FORCES", "FORCE_UNITS", "N"),
         ("moment", "MOMENTS", "MOMENT_UNITS", "Nmm"), ("power", "POWERS", "POWER_UNITS", "W")]


def strings(r, name):
    p = r.get(name)
    if p is None:
        return []
    if p.dimensions and len(p.dimensions) > 1:
        return [s.strip() for s in p.string_array]
    return [p.string_value.strip()]


def main():
    import c3d

    with open(sys.argv[1], "rb") as h:
        try:
            r = c3d.Reader(h)
        except Exception as e:  # noqa: BLE001 - any refusal is py-c3d's, reported
            print(json.dumps({"unreadable": str(e)}))
            return
        frames = [p.copy() for _, p, _ in r.read_frames(copy=True)]
        labels = [s.strip() for s in r.point_labels]
        P = np.array(frames)
        out = {}
        for kind, group, unit_name, default in KINDS:
            listed = set(strings(r, "POINT:" + group))
            unit = next((u for u in strings(r, "POINT:" + unit_name) if u), default)
            for i, label in enumerate(labels):
                if label in listed and label not in out:
                    values = []
                    for f in range(P.shape[0]):
                        xyz = P[f, i, :3]
                        ok = P[f, i, 3] >= 0 and np.all(np.isfinite(xyz))
                        values.append([float(v) for v in xyz] if ok else None)
                    out[label] = {"kind": kind, "unit": unit, "values": values}
    print(json.dumps({"points": labels, "outputs": out}))


if __name__ == "__main__":
    main()
