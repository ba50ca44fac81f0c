"""``motionx export``: write a motion file as a JSON clip, glTF 2.0 (.glb, or .gltf with
``--embedded``) or BVH (with the ground's description beside it, ``FILE.ground.json``), in the
world ``--world`` names."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from service.cli import CliError, add_command, load_motion
from solver.formats import EXPORT_WORLDS, EXPORTERS

CHOICES = tuple(EXPORTERS)  # the exporters' registry (solver.formats)


def cmd_export(args: argparse.Namespace) -> int:
    from solver.export import ExportError, export_motion, media_type

    fmt = "gltf" if args.format == "glb" else args.format  # glb: an alias of the binary glTF
    options: dict = {}
    if args.units is not None:
        if fmt != "bvh":
            raise CliError(f"--units applies to BVH only (format {fmt!r} is always in metres)")
        options["units"] = args.units
    if args.rig is not None:
        if fmt == "json":
            raise CliError("--rig applies to bvh, gltf and deepmimic (the JSON clip is on the motion's own skeleton)")
        if args.rig == "source" and args.units is not None:
            raise CliError("--units does not apply with --rig source (the input's own units are kept)")
        options["rig"] = args.rig
    if args.y_up and fmt == "json":
        options["y_up"] = True  # glTF and BVH are always Y-up: the flag changes nothing for them
    suffix = Path(args.out).suffix.lower() if args.out != "-" else ""
    if args.embedded:
        if args.format != "gltf":
            raise CliError("--embedded applies to --format gltf only (the .gltf JSON with its buffer embedded)")
        if suffix == ".glb":
            raise CliError("--embedded writes the .gltf JSON; name the file .gltf, or drop --embedded for a .glb")
        options["binary"] = False
    elif fmt == "gltf":
        if suffix == ".gltf":
            raise CliError("--format gltf writes the binary .glb; add --embedded for a .gltf JSON file, "
                           "or name the file .glb")
        if args.out == "-":
            raise CliError("--out - (stdout) is only for text formats; give a .glb file name "
                           "(or --embedded for the .gltf JSON)")
    if args.world is not None:
        if EXPORTERS[fmt].folder:
            raise CliError(f"--world does not apply to --format {fmt} (it writes the trial's own ground)")
        options["world"] = args.world
    if args.generic_model:
        if fmt != "opensim":
            raise CliError("--generic-model applies to --format opensim only")
        options["model"] = "generic"
    folder = EXPORTERS[fmt].folder
    if folder and (args.out == "-" or args.rig is not None or args.y_up):
        raise CliError(f"--format {fmt} writes a folder on the trial's own model: give --out DIR "
                       "(no stdout, --rig or --y-up)")
    motion = load_motion(args.motion)
    try:
        data = export_motion(motion, fmt, **options)
        if folder:
            return _write_folder(data, Path(args.out), args.format, motion)
    except ExportError as e:
        raise CliError(str(e)) from None
    if args.out == "-":
        sys.stdout.write(data)
        return 0
    out = Path(args.out)
    try:
        if isinstance(data, bytes):
            out.write_bytes(data)
        else:
            out.write_text(data)
    except OSError as e:
        raise CliError(f"cannot write {out}: {e.strerror or e}") from None
    frames, fps = _written_frames(motion, options)
    line = {"out": str(out), "format": args.format, "media_type": media_type(fmt, **options),
            "frames": frames, "fps": fps, "character": motion.character.name, "bytes": out.stat().st_size}
    if fmt == "bvh":
        line["ground"] = str(_write_ground(motion, out, options))
    print(json.dumps(line))
    return 0


def _written_frames(motion, options: dict) -> tuple[int, float]:
    """The frames and frame rate of the file written: the motion's own, or on the input's rig
    (``--rig source``) one gait cycle at the input's frame rate (a 60 fps BVH comes back at 60 fps), or on
    an OpenSim trial's model its bodies at the model's preview rate (``solver.export.opensim.preview_times``)."""
    if options.get("rig") != "source":
        return motion.T, motion.fps
    from solver.rig import SkeletonRig, output_times

    rig = motion.context.rig
    if isinstance(rig, SkeletonRig):
        t, _ = output_times(motion, rig.frame_time)
    elif rig is not None and rig.format == "opensim":
        from solver.export.opensim import preview_times

        t = preview_times(motion)
    else:
        return motion.T, motion.fps
    return int(t.size), (round(float(1.0 / (t[1] - t[0])), 6) if t.size > 1 else motion.fps)


def _write_ground(motion, out: Path, options: dict) -> Path:
    """BVH has no meshes: the ground's description (solver.export.world.ground_json) in the BVH's
    own axes and unit, as ``FILE.ground.json`` beside it."""
    from solver.export import ExportError
    from solver.export.world import ground_json

    path = out.with_suffix(".ground.json")
    keys = ("world", "rig", "units")
    try:
        text = ground_json(motion, **{k: options[k] for k in keys if k in options})
        path.write_text(text)
    except ExportError as e:
        raise CliError(str(e)) from None
    except OSError as e:
        raise CliError(f"cannot write {path}: {e.strerror or e}") from None
    return path


def _write_folder(data: bytes, out: Path, fmt: str, motion) -> int:
    """A folder format (OpenSim): the folder written, one JSON line with its files and residuals."""
    from solver.export import write_folder

    try:
        write_folder(data, out)
    except OSError as e:
        raise CliError(f"cannot write {out}: {e.strerror or e}") from None
    line = {"out": str(out), "format": fmt, "files": sorted(p.name for p in out.iterdir() if p.is_file()),
            "frames": motion.T, "fps": motion.fps, "character": motion.character.name}
    summary = out / "summary.json"
    if summary.is_file():
        res = json.loads(summary.read_text()).get("residuals", {}).get("as_written", {})
        line["residuals"] = {k: res.get(k) for k in ("peak_residual_force_vector_N", "force_limit_N",
                                                     "peak_residual_moment_Nm", "moment_limit_Nm", "meets_hicks_2015")}
    print(json.dumps(line))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "export", "export a motion file as a JSON clip, glTF 2.0 (.glb) or BVH", """\
Write a motion file for other tools: a compact JSON clip (schema solver/export/clip.schema.json),
glTF 2.0 binary .glb (skinned ellipsoids + animation, Y-up, metres; --embedded for a .gltf
JSON) or BVH (Y-up, cm by default), or, with --rig source, on the input's own skeleton (BVH, skinned
glTF, DeepMimic motion). The walk is written where gravity points down (--world gravity, the
default: a slope walk climbs a ramp, stairs rise, a curve keeps its path) with its ground beside
it (the GLB's "ground" node, the clip's "ground", FILE.ground.json beside a BVH); --world ground
keeps the solver's frame (level ground, a slope as tilted gravity). solver.export.reimport
reads the JSON clip, glTF and BVH back.""")
    s.add_argument("motion", metavar="MOTION.json", help="motion file v2 (JSON), e.g. a tutor or a λ optimum")
    s.add_argument("--format", required=True, choices=CHOICES,
                   help="json: motionx clip; gltf (alias glb): binary glTF 2.0 (.glb); bvh; opensim: a folder on "
                        "the OpenSim trial's own model (checked by OpenSim's inverse dynamics)")
    s.add_argument("--out", required=True, metavar="FILE",
                   help="output file (- for stdout, text formats only); a folder for --format opensim")
    s.add_argument("--generic-model", action="store_true",
                   help="with --format opensim, a motion not made from an OpenSim trial: write it on OpenSim's "
                        "gait2354 model scaled to the motion's character")
    s.add_argument("--embedded", action="store_true",
                   help="with --format gltf: the .gltf JSON with its buffer embedded (base64) instead of the .glb")
    s.add_argument("--y-up", action="store_true",
                   help="JSON clip in Y-up axes (x left, y up, z forward); glTF and BVH are always Y-up")
    s.add_argument("--units", choices=("cm", "m"), default=None, help="BVH length unit (default: cm)")
    s.add_argument("--rig", choices=("character", "source"), default=None,
                   help="source: on the input's own skeleton (the BVH, skinned glTF or DeepMimic character the "
                        "motion was made from: its hierarchy, names, offsets, channels; the joints the motion's "
                        "character locked carry the capture's own values at the same gait phase); character "
                        "(default): on the motion's own skeleton")
    s.add_argument("--world", choices=tuple(EXPORT_WORLDS), default=None,
                   help="gravity (default): gravity points down and the ground is as the walk found it (a slope "
                        "walk climbs its ramp: root and feet rise by travel × tan(slope)); ground: the solver's "
                        "own frame (level ground, a slope as tilted gravity)")
    s.set_defaults(func=cmd_export)
