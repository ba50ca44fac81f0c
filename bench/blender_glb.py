"""Import a motionx GLB (a library's or one motion's) in Blender, headless, and measure what a
DCC/game user gets: the import time, one armature with one bone per segment, one action per
animation, and seamless loops — every joint's local rotation at the loop's last frame equals
its first, and the pelvis moved by the loop transform the animation's extras state.

Not part of ``make bench`` (Blender is a 370 MB wheel for one Python version): in a venv of its
own, ``pip install bpy==4.5.15`` (Python 3.11), then ``python bench/blender_glb.py FILE.glb``.
Prints one JSON object. Measured on the demo's library: README, "The GLB in a game engine".
"""
import json
import math
import sys
import time

import bpy

path = sys.argv[-1]
bpy.ops.wm.read_factory_settings(use_empty=True)
with open(path, "rb") as fh:  # the GLB's JSON chunk: frame rate and each animation's loop (extras)
    head = fh.read(20)
    gltf = json.loads(fh.read(int.from_bytes(head[12:16], "little")))
fps = gltf["asset"]["extras"]["fps"]
loops = {a["name"]: a["extras"]["loop"] for a in gltf["animations"]}
bpy.context.scene.render.fps = int(round(fps))  # one Blender frame per motion frame
t = time.perf_counter()
bpy.ops.import_scene.gltf(filepath=path)
t_import = time.perf_counter() - t
arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
actions = sorted(a.name for a in bpy.data.actions)
out = {"blender": bpy.app.version_string, "import_s": round(t_import, 3), "bones": len(arm.data.bones),
       "meshes": sum(o.type == "MESH" for o in bpy.context.scene.objects), "actions": actions, "loops": {},
       "scene_fps": bpy.context.scene.render.fps}
scene = bpy.context.scene
for act in bpy.data.actions:
    arm.animation_data.action = act
    f0, f1 = loops[act.name]["start_frame"], loops[act.name]["end_frame"]
    worst = 0.0
    poses = {}
    for f in (f0, f1):
        scene.frame_set(f)
        poses[f] = {b.name: b.matrix_basis.to_quaternion() for b in arm.pose.bones}
        poses[f]["@root"] = (arm.matrix_world @ arm.pose.bones["pelvis"].matrix).copy()
    # the loop's last frame is the first under the root motion: compare non-root bones' local rotations
    m0, m1 = poses[f0].pop("@root"), poses[f1].pop("@root")
    tr = loops[act.name]["transform"]
    moved = (m1.translation - m0.translation)
    moved.z = 0.0  # Blender: Z up; the cycle's displacement is horizontal
    turn = math.degrees(m1.to_quaternion().to_euler("XYZ").z - m0.to_quaternion().to_euler("XYZ").z)
    turn = (turn + 180) % 360 - 180
    root = {"displacement_m": round(moved.length, 6), "extras_displacement_m": round(math.hypot(*tr["translation"]), 6),
            "turn_deg": round(turn, 4), "extras_yaw_deg": tr["yaw_deg"]}
    for name in poses[f0]:
        if name == "pelvis":
            continue
        q0, q1 = poses[f0][name], poses[f1][name]
        worst = max(worst, math.degrees(q0.rotation_difference(q1).angle))
    out["loops"][act.name] = {"frames": [f0, f1], "range": list(act.frame_range),
                              "max_joint_mismatch_deg": round(worst, 6), **root}
print(json.dumps(out))
