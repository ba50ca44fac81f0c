"""The motion's physical context (``solver.motion.MotionContext``): typed on the motion, stored in
the motion file under the keys earlier versions wrote, and never read back from ``provenance``
by string key in the physics code (solver/, mjcf/)."""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import numpy as np
import pytest

from solver.capture import GroundFrame
from solver.character import reference
from solver.environment import Environment
from solver.motion import CONTEXT_KEYS, Cycle, GaitReference, Motion, MotionContext, MotionError
from solver.realism import requested_heading
from solver.retargeting import Rig
from solver.rig import SkeletonRig

ROOT = Path(__file__).resolve().parents[1]


def _walk(T: int = 12) -> Motion:
    ch = reference("halfboy")
    q = 0.05 * np.random.default_rng(0).standard_normal((ch.n, T))
    return Motion(ch, 15.0, q, reference_name="halfboy", provenance={"step": "extrapolate", "lambda": 0.5})


#: a one-joint BVH rig as a motion file holds it
ONE_JOINT_RIG = {"format": "bvh", "names": ["Hips"], "parents": [-1], "offsets": [[0.0, 0.0, 0.0]],
                 "channels": [["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"]],
                 "roles": {"pelvis": 0}, "times": [0.0, 0.1], "local": [[[1.0, 0.0, 0.0, 0.0]], [[1.0, 0.0, 0.0, 0.0]]],
                 "root": [[0.0, 90.0, 0.0], [5.0, 90.0, 0.0]]}

#: a λ optimum's provenance as the motion files of earlier versions hold it (every context key at
#: the top level of ``provenance``, the captured cycle inside ``source``)
OLD_PROVENANCE = {
    "step": "extrapolate",
    "source": {"format": "c3d", "files": ["walk.c3d"], "subject": {"mass_kg": 70.0},
               "cycle": {"start": "right", "index": 0, "frames": [10, 25], "t_start": 0.66, "period_s": 1.02,
                         "overlap_frames": 2}},
    "frame": {"R": [[1, 0, 0], [0, 0, -1], [0, 1, 0]], "offset": [0.1, 0.0, 0.2], "unit_m": 0.001,
              "velocity": [0.0, 0.0, 0.0], "axes": "y up"},
    "lambda": 0.5,
    "environment": {"gravity": [0.0, -1.7, -9.66], "friction": 0.8, "terrain": {"step_height_m": 0.1}},
    "environment_values": {"slope_deg": 10.0, "curve_deg": 20.0},
    "target": {"slope_deg": 20.0, "curve_deg": 40.0},
    "continuation": {"method": "adaptive", "step": 3},
    "heading_change_deg": 21.0,
    "tutor_heading_change_deg": 1.0,
    "gait_reference": {"capture": {"cadence_steps_per_min": 104.0}, "tutor": None, "fit": {"marker_rms_mm": 9.5}},
    "rig": ONE_JOINT_RIG,
    "created": "2026-01-01T00:00:00+00:00",
}


def _old_file(provenance: dict) -> dict:
    d = _walk().to_dict()
    d["provenance"] = json.loads(json.dumps(provenance))
    return d


def test_an_old_motion_file_loads_with_its_context_and_is_written_back_the_same():
    m = Motion.from_dict(_old_file(OLD_PROVENANCE))
    ctx = m.context
    assert m.environment == Environment((0.0, -1.7, -9.66), 0.8, 0.1) and ctx.environment is not None
    assert ctx.axis_values == {"slope_deg": 10.0, "curve_deg": 20.0}
    assert isinstance(ctx.frame, GroundFrame) and m.frame.unit_m == 0.001 and m.frame.axes == "y up"
    assert np.allclose(m.frame.offset, [0.1, 0.0, 0.2])
    assert isinstance(ctx.rig, SkeletonRig) and ctx.rig.names == ("Hips",) and ctx.rig.frame_time == 0.1
    assert ctx.rig.to_dict() == ONE_JOINT_RIG  # written back as read
    assert ctx.cycle is not None and (ctx.cycle.t_start, ctx.cycle.period_s) == (0.66, 1.02)
    assert ctx.cycle.record["frames"] == [10, 25]
    assert (ctx.heading_change_deg, ctx.tutor_heading_change_deg, ctx.heading_change_requested_deg) == (21.0, 1.0, None)
    assert ctx.gait_reference == GaitReference({"cadence_steps_per_min": 104.0}, None, {"marker_rms_mm": 9.5})
    # provenance keeps where the motion came from, and nothing of its context
    assert set(m.provenance) == {"step", "source", "lambda", "target", "continuation", "created"}
    assert m.provenance["source"] == {"format": "c3d", "files": ["walk.c3d"], "subject": {"mass_kg": 70.0}}
    # the file written back holds the same keys and values (a tutor's ``gait_reference`` has no ``tutor``)
    back = m.to_dict()["provenance"]
    want = {**OLD_PROVENANCE, "gait_reference": {k: v for k, v in OLD_PROVENANCE["gait_reference"].items()
                                                 if v is not None}}
    assert back == json.loads(json.dumps(want))
    again = Motion.from_dict(json.loads(m.to_json()))
    assert again.context.to_provenance() == ctx.to_provenance() and again.context.cycle == ctx.cycle


def test_a_version_1_file_with_a_partial_provenance_loads():
    d = _old_file({"step": "tutor", "environment": {"gravity": [0, 0, -9.81], "friction": 1.0}, "lambda": 0.0})
    d["version"] = 1
    d.pop("trajectory", None)
    m = Motion.from_dict(d)
    assert m.environment == Environment() and m.context.environment is not None
    assert m.context.frame is None and m.frame.unit_m == 1.0 and m.context.cycle is None and m.context.rig is None
    assert "frame" not in m.to_dict()["provenance"]  # nothing the file did not say is added


def test_files_before_environment_values_give_the_curve_from_target_and_lambda():
    m = Motion.from_dict(_old_file({"target": {"curve_deg": 90.0}, "lambda": 0.5}))
    assert m.context.axis_values == {"curve_deg": 45.0}
    assert requested_heading(m) == (45.0, "environment_values.curve_deg (a straight tutor assumed)")
    assert requested_heading(Motion.from_dict(_old_file({"heading_change_deg": 10.0}))) == (10.0, "heading_change_deg")


@pytest.mark.parametrize("key, value, needle", [
    ("environment", {"friction": 0}, "provenance.environment: friction"),
    ("frame", {"R": "up"}, "provenance.frame"),
    ("rig", [1, 2], "provenance.rig"),
    ("rig", {"format": "bvh", "names": ["Hips"]}, "provenance.rig: the motion's source rig is unreadable"),
    ("rig", {"format": "fbx"}, "provenance.rig: unknown rig format 'fbx'"),
    ("environment_values", "flat", "provenance.environment_values"),
    ("source", {"cycle": 3}, "provenance.source.cycle"),
])
def test_a_context_value_of_the_wrong_kind_is_refused_naming_its_key(key, value, needle):
    with pytest.raises(MotionError, match=needle.replace(".", r"\.")):
        Motion.from_dict(_old_file({key: value}))


def test_context_keys_are_refused_in_provenance():
    m = _walk()
    for key in CONTEXT_KEYS.values():
        with pytest.raises(MotionError, match="context"):
            m.evolve(provenance={**m.provenance, key: {}})
    with pytest.raises(MotionError, match=r"source\.cycle"):
        m.evolve(provenance={"source": {"cycle": {"t_start": 0.0}}})
    with pytest.raises(MotionError, match="MotionContext"):
        m.evolve(context={"environment": {}})


def test_the_context_is_typed_and_immutable():
    ctx = MotionContext(environment=Environment(friction=0.5), cycle=Cycle(0.5, 1.1, {"index": 0}),
                        heading_change_deg=3, rig=Rig.from_dict(ONE_JOINT_RIG))
    m = _walk().evolve(context=ctx)
    assert m.environment.friction == 0.5 and m.context.heading_change_deg == 3.0
    with pytest.raises(AttributeError):
        m.context.heading_change_deg = 4.0  # type: ignore[misc]
    assert m.evolve(q=m.q + 0.01).context is ctx  # a changed motion keeps its context
    moved = m.context.with_(heading_change_deg=5.0)
    assert moved.heading_change_deg == 5.0 and m.context.heading_change_deg == 3.0
    with pytest.raises(MotionError, match="heading_change_deg"):
        MotionContext(heading_change_deg=math.nan)
    with pytest.raises(MotionError, match="environment"):
        MotionContext(environment={"friction": 1.0})  # type: ignore[arg-type]
    with pytest.raises(MotionError, match=r"context\.rig must be a Rig"):
        MotionContext(rig=ONE_JOINT_RIG)  # type: ignore[arg-type]
    d = m.to_dict()["provenance"]
    assert d["source"] == {"cycle": {"index": 0, "t_start": 0.5, "period_s": 1.1}} and d["rig"] == ONE_JOINT_RIG


# --- no physics code reads the context from provenance --------------------------------------------------

#: the keys a context is stored under in a motion file (and the cycle, inside ``source``)
FORBIDDEN = frozenset(CONTEXT_KEYS.values()) | {"cycle"}


def _key_of(node: ast.AST) -> str | None:
    """The string key a node reads (``x["k"]``, ``x.get("k")``, ``x.pop("k")``, ``"k" in x``), else None."""
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, str):
        return node.slice.value
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
            and node.func.attr in ("get", "pop", "setdefault") and node.args
            and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
        return node.args[0].value
    if (isinstance(node, ast.Compare) and isinstance(node.left, ast.Constant) and isinstance(node.left.value, str)
            and any(isinstance(op, (ast.In, ast.NotIn)) for op in node.ops)):
        return node.left.value
    return None


def _read_from(node: ast.AST) -> ast.AST:
    if isinstance(node, ast.Subscript):
        return node.value
    if isinstance(node, ast.Call):
        return node.func.value  # type: ignore[attr-defined]
    return node.comparators[0]  # type: ignore[attr-defined]


def provenance_context_reads(source: str) -> list[tuple[int, str]]:
    """(line, key) of every read of a context key from a motion's provenance: from an expression
    that mentions ``.provenance`` (``m.provenance["rig"]``, ``(m.provenance.get("source") or
    {}).get("cycle")``) or from a name the same function assigned from one (``prov = m.provenance;
    prov.get("frame")``)."""
    tree = ast.parse(source)
    out: set[tuple[int, str]] = set()
    functions = (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)

    def own(scope: ast.AST) -> list[ast.AST]:
        """The nodes of a scope, not those of the functions defined in it."""
        nodes, todo = [], list(ast.iter_child_nodes(scope))
        while todo:
            n = todo.pop()
            nodes.append(n)
            if not isinstance(n, functions):
                todo.extend(ast.iter_child_nodes(n))
        return nodes

    for scope in [tree, *(n for n in ast.walk(tree) if isinstance(n, functions))]:
        aliases: set[str] = set()
        body = own(scope)

        def from_provenance(expr: ast.AST) -> bool:
            return any((isinstance(n, ast.Attribute) and n.attr == "provenance")
                       or (isinstance(n, ast.Name) and n.id in aliases) for n in ast.walk(expr))

        def names(t: ast.AST) -> set[str]:
            return {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}

        for _ in range(3):  # aliases of aliases
            for node in body:
                if isinstance(node, ast.Assign):
                    for t in node.targets:
                        if isinstance(t, ast.Tuple) and isinstance(node.value, ast.Tuple) \
                                and len(t.elts) == len(node.value.elts):
                            aliases |= {n for te, ve in zip(t.elts, node.value.elts) if from_provenance(ve)
                                        for n in names(te)}
                        elif from_provenance(node.value):
                            aliases |= names(t)
                elif isinstance(node, (ast.AnnAssign, ast.NamedExpr)) and node.value is not None \
                        and from_provenance(node.value):
                    aliases |= names(node.target)
        for node in body:
            key = _key_of(node)
            if key in FORBIDDEN and from_provenance(_read_from(node)):
                out.add((node.lineno, key))
    return sorted(out)


def test_the_scan_finds_the_reads_it_looks_for():
    src = '''
def f(motion, tutor):
    a = motion.provenance["rig"]
    b = (motion.provenance.get("source") or {}).get("cycle")
    prov = tutor.provenance
    c = prov.get("environment")
    d = "gait_reference" in prov
    src = prov["source"]
    e = src["cycle"]["t_start"]
    ok = motion.provenance.get("step"), motion.context.rig, motion.provenance["lambda"], rig["frame"]
    p, c = motion.provenance, motion.context
    f = p["frame"], c["frame"]


def g(capture):
    src = capture.source
    return src["cycle"], capture.provenance["heading_change_deg"]
'''
    assert provenance_context_reads(src) == [(3, "rig"), (4, "cycle"), (6, "environment"), (7, "gait_reference"),
                                             (9, "cycle"), (12, "frame"), (17, "heading_change_deg")]


def test_no_physics_code_reads_the_context_from_provenance():
    """solver/ and mjcf/ read a motion's environment, rig, frame, cycle, headings and gait reference
    from ``motion.context`` (``solver/motion.py``, which maps the file's keys, aside)."""
    found = []
    for pkg in ("solver", "mjcf"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if path == ROOT / "solver" / "motion.py":
                continue
            found += [f"{path.relative_to(ROOT)}:{line}: provenance[{key!r}]"
                      for line, key in provenance_context_reads(path.read_text())]
    assert not found, "read these from motion.context instead:\n" + "\n".join(found)
