#!/usr/bin/env python3
"""Import an FBX in Blender (the `bpy` module from PyPI, run outside the test suite: it is a
350 MB wheel) the way a user does, with the importer's defaults, and print its armature's
bone heads in world space (Blender's metres, +Z up) at the first, middle and last frame of
the scene, with the scene's rate:

  {"fps": F, "frame_start": A, "frame_end": B, "bones": [names],
   "frames": {"A": [[x, y, z], ...], ...}}

    python -m venv /tmp/bpy && /tmp/bpy/bin/pip install bpy
    /tmp/bpy/bin/python scripts/blender-fbx.py take.fbx out.json

Blender's frame f is FBX time (f - 1) / fps; a glTF's +Y-up (x, y, z) is Blender's (x, -z, y).
"""
import json
import sys

import bpy


def main():
    path, out = sys.argv[1], sys.argv[2]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=path)
    arm = [o for o in bpy.data.objects if o.type == "ARMATURE"][0]
    scene = bpy.context.scene
    res = {
        "fps": scene.render.fps / scene.render.fps_base,
        "frame_start": scene.frame_start,
        "frame_end": scene.frame_end,
        "bones": [b.name for b in arm.pose.bones],
        "frames": {},
    }
    for f in [scene.frame_start, (scene.frame_start + scene.frame_end) // 2, scene.frame_end]:
        scene.frame_set(f)
        res["frames"][f] = [list(arm.matrix_world @ b.head) for b in arm.pose.bones]
    with open(out, "w") as h:
        json.dump(res, h)


if __name__ == "__main__":
    main()
