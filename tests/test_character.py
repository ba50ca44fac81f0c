import dataclasses
import math

import numpy as np
import pytest

from solver import character as C
from solver.kinematics import segment_frames


@pytest.mark.parametrize("name,n", [("halfboy", 16), ("fullbody", 43), ("capture-lower", 30), ("capture-full", 63)])
def test_reference_characters_have_the_specified_coordinates(name, n):
    ch = C.reference(name)
    assert ch.n == n
    assert ch.coordinate_names[:6] == ("root_tx", "root_ty", "root_tz", "root_rz", "root_ry", "root_rx")
    assert ch.dof_kinds[:3] == ("slide",) * 3 and ch.dof_kinds[3:6] == ("hinge",) * 3
    assert math.isclose(ch.total_mass, 23.0, rel_tol=1e-12)
    assert {c.name for c in ch.contacts} == {"heel_r", "toe_r", "heel_l", "toe_l"}
    assert {f.side for f in ch.feet} == {"right", "left"}


def test_halfboy_dofs_are_the_thesis_ones():
    ch = C.halfboy()
    # root 6, each hip 3, each knee 1, each ankle 1
    per_side = ["hip_flexion", "hip_adduction", "hip_rotation", "knee_angle", "ankle_angle"]
    assert set(ch.coordinate_names[6:]) == {f"{j}_{s}" for j in per_side for s in "rl"}


def test_ellipsoid_matches_spec_3_1_to_3_4():
    length, mass, rho = 0.4, 2.3, 1050.0
    a, b, inertia = C.ellipsoid(length, mass, rho)
    assert a == pytest.approx(0.2)
    # the ellipsoid's volume times density is its mass
    assert 4.0 / 3.0 * math.pi * a * b * b * rho == pytest.approx(mass)
    assert np.allclose(np.diag(inertia), [mass * 2 * b * b / 5, mass * (a * a + b * b) / 5, mass * (a * a + b * b) / 5])


def test_segment_inertia_follows_its_direction():
    seg = C.build_segment(C.SegmentSpec("s", None, (0, 0, 0), C.root_dofs(), 0.5, 3.0, direction=(0, 0, -1)))
    a, b, _ = C.ellipsoid(0.5, 3.0, 1050.0)
    assert np.allclose(seg.com, [0, 0, -a])
    # the long axis (smallest moment) is z
    assert np.argmin(np.diag(seg.inertia)) == 2
    assert np.allclose(seg.marker, [0, 0, -0.5])


def test_winter_fractions_sum_to_the_body():
    ch = C.capture_full(1.8, 70.0)
    assert ch.total_mass == pytest.approx(70.0)
    thigh = ch.segment("thigh_r")
    assert thigh.mass == pytest.approx(7.0)
    assert thigh.length == pytest.approx(0.245 * 1.8)


def test_reduce_welds_segments_without_changing_mass_or_com():
    cap = C.capture_lower()
    hb = C.halfboy()
    q_cap = np.zeros(cap.n)
    q_hb = np.zeros(hb.n)
    rc, pc = segment_frames(cap, q_cap)
    rh, ph = segment_frames(hb, q_hb)
    # every segment is where it was (locked at 0)
    assert np.allclose(pc, ph) and np.allclose(rc, rh)
    # total mass and the model's composite centre of mass are unchanged
    m_cap, m_hb = cap.model, hb.model
    assert sum(m_cap.mass) == pytest.approx(sum(m_hb.mass))
    assert len(hb.segments) == len(cap.segments)  # toes kept, welded to the feet
    assert m_hb.seg_body["toes_r"] == m_hb.seg_body["foot_r"]


def test_characters_are_immutable():
    ch = C.halfboy()
    with pytest.raises(dataclasses.FrozenInstanceError):
        ch.name = "x"  # type: ignore[misc]
    with pytest.raises(ValueError):
        ch.segments[1].offset[0] = 1.0


def test_bad_descriptions_are_refused_with_a_message():
    good = C.SegmentSpec("pelvis", None, (0, 0, 0), C.root_dofs(), 0.2, 10.0)
    with pytest.raises(C.CharacterError, match="parent 'nope'"):
        C.build_character("x", [good, C.SegmentSpec("a", "nope", (0, 0, 0), (), 0.1, 1.0)])
    with pytest.raises(C.CharacterError, match="axis"):
        C.Dof("j", "hinge", np.zeros(3))
    with pytest.raises(C.CharacterError, match="kind"):
        C.Dof("j", "ball", np.array([0, 0, 1.0]))
    with pytest.raises(C.CharacterError, match="length"):
        C.build_character("x", [C.SegmentSpec("pelvis", None, (0, 0, 0), C.root_dofs(), -1.0, 10.0)])
    with pytest.raises(C.CharacterError, match="non-finite"):
        C.build_character("x", [C.SegmentSpec("pelvis", None, (0, float("nan"), 0), C.root_dofs(), 0.2, 10.0)])
    with pytest.raises(C.CharacterError, match="unknown coordinates"):
        C.halfboy().reduce(["elbow_flexion_r"])
    with pytest.raises(C.CharacterError, match="unknown character"):
        C.reference("robot")


def test_singular_dofs_are_the_middle_of_each_ball_joint():
    ch = C.capture_lower()
    names = [ch.coordinate_names[i] for i in ch.singular_dofs]
    assert "hip_adduction_r" in names and "knee_adduction_l" in names and "root_ry" in names


def test_merge_in_a_posture_keeps_the_whole_body_com():
    """Merging the upper body in the posture it has keeps the whole-body centre of mass."""
    from solver.kinematics import segment_frames

    ch = C.capture_full()
    pose = {"lumbar_flexion": 0.35, "thorax_flexion": 0.1, "shoulder_flexion_r": 0.4, "elbow_flexion_l": 0.8}
    q = np.zeros(ch.n)
    for k, v in pose.items():
        q[ch.index(k)] = v

    def com(character, qv):
        rots, poss = segment_frames(character, qv)
        total = sum(s.mass * (poss[i] + rots[i] @ s.com) for i, s in enumerate(character.segments))
        return total / character.total_mass

    merged = C.merge_segments(ch, ["abdomen"], pose=pose)
    q_low = np.array([q[ch.index(nm)] for nm in merged.coordinate_names])
    assert merged.total_mass == pytest.approx(ch.total_mass)
    assert np.allclose(com(merged, q_low), com(ch, q), atol=1e-12)
    flat = C.merge_segments(ch, ["abdomen"])
    assert not np.allclose(com(flat, q_low), com(ch, q), atol=1e-3)  # the posture matters


def test_the_sole_is_found_by_name_whatever_the_contact_order():
    """``Character.sole_indices``: the heel and toe points by name, in any order of ``contacts``;
    ``has_soles`` for two feet of two points each."""
    ch = C.reference("halfboy")
    assert ch.has_soles
    for side in ("right", "left"):
        h, t = ch.sole_indices(side)
        assert ch.contacts[h].name.startswith("heel") and ch.contacts[t].name.startswith("toe")
    flipped = dataclasses.replace(ch, contacts=tuple(reversed(ch.contacts)))
    for side in ("right", "left"):
        h, t = flipped.sole_indices(side)
        assert flipped.contacts[h] is ch.sole(side).heel and flipped.contacts[t] is ch.sole(side).toe
    one_point = dataclasses.replace(ch, contacts=tuple(c for c in ch.contacts if not c.name.startswith("toe")))
    assert not one_point.has_soles


def test_foot_geometry_is_read_from_the_character_only():
    """No module sorts contact points by their x to find a heel or a toe (the character's sole
    names them, ``solver/character/base.py``), and the optimizer, exporters and MuJoCo take no foot
    geometry from the naturalness checks."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    sorts, imports = [], []
    for path in sorted([*(root / "solver").rglob("*.py"), *(root / "mjcf").rglob("*.py")]):
        rel = str(path.relative_to(root))
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) in (
                    "sorted", "min", "max", "sort"):
                text = " ".join(ast.unparse(k.value) for k in node.keywords if k.arg == "key")
                text += " ".join(ast.unparse(a) for a in node.args)  # sorted([(c.position[0], i), ...])
                if "position[0]" in text and rel != "solver/character/base.py":
                    sorts.append(f"{rel}:{node.lineno}")
            if isinstance(node, ast.ImportFrom) and node.module == "solver.naturalness" and (
                    rel.startswith(("solver/spacetime/", "solver/export/", "mjcf/"))):
                feet = {a.name for a in node.names} & {"sole_corners", "heel_toe", "has_two_point_feet"}
                if feet:
                    imports.append(f"{rel}:{node.lineno} {sorted(feet)}")
    assert not sorts, f"contact points sorted by x (use Character.sole): {sorts}"
    assert not imports, f"foot geometry from the naturalness checks (use Character.sole): {imports}"
