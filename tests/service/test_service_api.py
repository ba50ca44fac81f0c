"""The HTTP API over a real uvicorn process (embedded default: SQLite + local runner)."""

from __future__ import annotations

import json
import math

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from svc_util import KEY_A, halfboy_motion

PROBLEM = "application/problem+json"


def upload(client: httpx.Client, motion_dict: dict | str, **kw) -> httpx.Response:
    body = motion_dict if isinstance(motion_dict, str) else json.dumps(motion_dict)
    return client.post("/motions", content=body, headers={"content-type": "application/json"}, **kw)


def assert_problem(r: httpx.Response, status: int, *needles: str) -> dict:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith(PROBLEM), r.headers
    body = r.json()
    assert body["status"] == status and body["title"] and isinstance(body["detail"], str)
    for n in needles:
        assert n in body["detail"], (n, body["detail"])
    return body


@pytest.fixture(scope="module")
def motion_id(api) -> str:
    r = upload(api.a, halfboy_motion().to_dict(), params={"name": "walk"})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def test_axes_endpoint_is_the_solvers_registry_and_the_target_schema_follows_it(api):
    from solver import axes as registry

    assert api.anon.get("/axes").status_code == 401  # like every endpoint but /health, /openapi.json and /docs
    r = api.a.get("/axes")  # the page builds its words from it, with the key
    assert r.status_code == 200
    got = r.json()["axes"]
    assert [a["name"] for a in got] == list(registry.names())
    speed = next(a for a in got if a["name"] == "speed_scale")
    assert (speed["minimum"], speed["maximum"], speed["default"], speed["unit"]) == (0.5, 2.0, 1.0, "×")
    target = api.anon.get("/openapi.json").json()["components"]["schemas"]["TargetIn"]["properties"]
    assert list(target) == list(registry.names())


def test_health_and_openapi(api):
    assert api.anon.get("/health").json()["status"] == "ok"
    doc = api.anon.get("/openapi.json").json()
    assert doc["openapi"].startswith("3.")
    assert "MotionFileV1" in doc["components"]["schemas"]
    for path in ("/motions", "/motions/{motion_id}", "/motions/{motion_id}/extrapolate", "/jobs/{job_id}",
                 "/jobs/{job_id}/motions", "/jobs/{job_id}/cancel", "/jobs/{job_id}/events"):
        assert path in doc["paths"]


def test_api_key_required(api, motion_id):
    assert_problem(api.anon.get(f"/motions/{motion_id}"), 401, "API key")
    r = api.anon.get(f"/motions/{motion_id}", headers={"X-API-Key": "nope"})
    assert_problem(r, 401, "invalid")
    assert r.headers["www-authenticate"] == "Bearer"
    r = api.anon.get(f"/motions/{motion_id}?format=motion", headers={"Authorization": f"Bearer {KEY_A}"})
    assert r.status_code == 200


def test_other_keys_get_404(api, motion_id):
    assert_problem(api.b.get(f"/motions/{motion_id}"), 404)
    assert_problem(api.b.get(f"/motions/{motion_id}/validation"), 404)
    assert_problem(api.b.post(f"/motions/{motion_id}/extrapolate", json={"target": {"slope_deg": 2}}), 404)
    r = api.a.post(f"/motions/{motion_id}/extrapolate", json={"target": {"friction": 0.5}})
    assert r.status_code == 202
    job = r.json()["id"]
    for path in (f"/jobs/{job}", f"/jobs/{job}/motions", f"/jobs/{job}/events"):
        assert_problem(api.b.get(path), 404)
    assert_problem(api.b.post(f"/jobs/{job}/cancel"), 404)
    assert all(m["id"] != motion_id for m in api.b.get("/motions").json()["items"])


def test_upload_returns_location_and_round_trips_exactly(api):
    m = halfboy_motion(seed=5)
    r = upload(api.a, m.to_dict())
    assert r.status_code == 201 and r.headers["location"] == f"/motions/{r.json()['id']}"
    info = r.json()
    assert (info["kind"], info["character"], info["frames"], info["coordinates"]) == ("capture", "halfboy", 12, 16)
    got = api.a.get(r.headers["location"], params={"format": "motion"}).json()
    assert got["frames"] == m.to_dict()["frames"]


def test_clip_is_the_default_format(api, motion_id):
    r = api.a.get(f"/motions/{motion_id}")
    assert r.status_code == 200 and r.headers["content-type"].startswith("application/json")
    assert r.json()["format"] == "motionx.clip"
    r = api.a.get(f"/motions/{motion_id}", params={"y_up": "true", "decimals": "3"})
    assert r.json()["axes"]["up"] == "+y"
    assert_problem(api.a.get(f"/motions/{motion_id}", params={"nonsense": "1"}), 422, "nonsense")
    assert_problem(api.a.get(f"/motions/{motion_id}", params={"format": "fbx"}), 422)
    for fmt in ("bvh", "gltf", "glb"):
        assert api.a.get(f"/motions/{motion_id}", params={"format": fmt}).status_code == 200, fmt


def test_gltf_is_the_binary_glb_and_reimports_to_the_uploaded_motion(api):
    from solver.export.reimport import motion_from_bvh, motion_from_clip, motion_from_gltf

    m = halfboy_motion(seed=9)
    mid = upload(api.a, m.to_dict()).json()["id"]
    r = api.a.get(f"/motions/{mid}", params={"format": "gltf"})
    assert r.status_code == 200 and r.headers["content-type"] == "model/gltf-binary"
    assert r.content[:4] == b"glTF"
    glb = api.a.get(f"/motions/{mid}", params={"format": "glb"})  # the alias
    assert glb.headers["content-type"] == "model/gltf-binary" and glb.content == r.content
    back = motion_from_gltf(r.content, m.character)
    assert abs(back.q - m.q).max() < 1e-5 and back.fps == m.fps
    r = api.a.get(f"/motions/{mid}", params={"format": "gltf", "binary": "false"})  # the embedded .gltf JSON
    assert r.status_code == 200 and r.headers["content-type"].startswith("model/gltf+json")
    assert abs(motion_from_gltf(r.text, m.character).q - m.q).max() < 1e-5
    r = api.a.get(f"/motions/{mid}", params={"format": "gltf", "meshes": "false"})
    assert r.headers["content-type"] == "model/gltf-binary" and len(r.content) < len(glb.content)
    assert abs(motion_from_clip(api.a.get(f"/motions/{mid}").json(), m.character).q - m.q).max() < 1e-5
    bvh = api.a.get(f"/motions/{mid}", params={"format": "bvh"})
    assert abs(motion_from_bvh(bvh.text, m.character).q - m.q).max() < 1e-6
    assert_problem(api.a.get(f"/motions/{mid}", params={"format": "glb", "binary": "false"}), 422, "binary")
    assert_problem(api.a.get(f"/motions/{mid}", params={"format": "gltf", "binary": "maybe"}), 422, "binary")


def test_world_option_puts_a_slope_walk_on_its_ramp(api):
    """A motion made under gravity tilted by 10° (a +10° slope) downloads climbing its ramp (the
    default world, gravity down: the root turned by R_y(−10°) about the origin), or with
    ``world=ground`` in the solver's frame, as uploaded; an unknown world is a 422 naming both."""
    import numpy as np

    from solver.environment import Environment
    from solver.export.reimport import motion_from_bvh, motion_from_gltf

    m = halfboy_motion(seed=11)
    a = math.radians(10.0)
    env = Environment((-9.81 * math.sin(a), 0.0, -9.81 * math.cos(a)), 1.0)
    m = m.evolve(context=m.context.with_(environment=env))
    mid = upload(api.a, m.to_dict()).json()["id"]
    level = motion_from_gltf(api.a.get(f"/motions/{mid}", params={"format": "glb", "world": "ground"}).content,
                             m.character)
    assert abs(level.q - m.q).max() < 1e-5
    R = np.array([[math.cos(a), 0.0, -math.sin(a)], [0.0, 1.0, 0.0], [math.sin(a), 0.0, math.cos(a)]])
    for fmt, read in (("glb", motion_from_gltf), ("bvh", motion_from_bvh)):
        r = api.a.get(f"/motions/{mid}", params={"format": fmt})
        ramp = read(r.content if fmt == "glb" else r.text, m.character)
        np.testing.assert_allclose(ramp.q[:3], R @ m.q[:3], atol=1e-5)  # the root (x, y, z) on the ramp
    clip = api.a.get(f"/motions/{mid}").json()
    assert clip["world"]["name"] == "gravity" and clip["world"]["gravity"] == pytest.approx([0.0, 0.0, -9.81])
    assert clip["ground"]["normal"] == pytest.approx([-math.sin(a), 0.0, math.cos(a)], abs=1e-6)
    assert api.a.get(f"/motions/{mid}", params={"world": "ground"}).json()["world"]["name"] == "ground"
    assert_problem(api.a.get(f"/motions/{mid}", params={"format": "bvh", "world": "level"}), 422, "'gravity'",
                   "'ground'", "level")


# --- bad uploads: a clear 422 naming the problem, nothing stored --------------------------


def count_motions(api) -> int:
    return api.a.get("/motions", params={"limit": 1}).json()["total"]


@pytest.mark.parametrize(
    "mutate, needle",
    [
        (lambda d: d["frames"][2].__setitem__(3, "NaN"), "NaN"),
        (lambda d: d["frames"][2].__setitem__(3, "Infinity"), "Infinity"),
        (lambda d: d["frames"][2].__setitem__(3, "1e999"), "not finite"),
        (lambda d: d["frames"][4].pop(), "frames[4] has 15 values, expected 16"),
        (lambda d: d["coordinates"].__setitem__(0, "tail_wag"), "tail_wag"),
        (lambda d: d.__setitem__("character", {"reference": "robot"}), "robot"),
        (lambda d: d.__setitem__("fps", -3), "fps"),
        (lambda d: d.__setitem__("frames", d["frames"][:2]), "frames"),
        (lambda d: d.pop("format"), "format"),
        # an environment no job, plot or export could use is refused at upload, not answered 500 later
        (lambda d: d.setdefault("provenance", {}).__setitem__("environment", {"friction": 0}), "friction"),
        (lambda d: d.setdefault("provenance", {}).__setitem__("environment", {"friction": -1}), "friction"),
        (lambda d: d.setdefault("provenance", {}).__setitem__("environment", {"gravity": [0, 0, 1e300]}),
         "gravity must be finite"),
        (lambda d: d.setdefault("provenance", {}).__setitem__("environment", {"gravity": [0, 0, 0]}), "gravity"),
        (lambda d: d.setdefault("provenance", {}).__setitem__("environment", {"friction": "slippery"}),
         "provenance/environment/friction"),
    ],
    ids=["nan", "infinity", "overflow", "ragged", "unknown-joint", "unknown-character", "fps", "too-short",
         "not-a-motion-file", "friction-0", "friction-negative", "gravity-huge", "gravity-0", "friction-text"],
)
def test_bad_motion_files(api, mutate, needle):
    before = count_motions(api)
    d = halfboy_motion().to_dict()
    mutate(d)
    text = json.dumps(d).replace('"NaN"', "NaN").replace('"Infinity"', "Infinity").replace('"1e999"', "1e999")
    assert_problem(upload(api.a, text), 422, needle)
    assert count_motions(api) == before


def test_wrench_and_contact_shapes_checked(api):
    from solver.motion import Motion

    m = halfboy_motion()
    import numpy as np

    full = Motion(character=m.character, fps=m.fps, q=m.q, reference_name="halfboy",
                  contacts=np.ones((len(m.character.contacts), m.T), bool), wrenches=np.zeros((2, 6, m.T)))
    d = full.to_dict()
    d["wrenches"]["feet"]["left"][3] = [0.0] * 5
    assert_problem(upload(api.a, d), 422, "wrenches.feet.left[3] has 5 values, expected 6")
    d = full.to_dict()
    d["contacts"]["active"][1] = [1]
    assert_problem(upload(api.a, d), 422, "contacts.active[1]")
    r = upload(api.a, full.to_dict())
    assert r.status_code == 201 and r.json()["kind"] == "motion" and r.json()["has_wrenches"]


def test_not_json_and_wrong_media_type(api):
    assert_problem(upload(api.a, "{not json"), 422, "not valid JSON")
    assert_problem(upload(api.a, "[1, 2, 3]"), 422)
    r = api.a.post("/motions", content=b"hello", headers={"content-type": "text/plain"})
    assert_problem(r, 415, "application/json")


def test_oversized_bodies_get_413(api):
    limit = 2 * 1024 * 1024
    r = api.a.post("/motions", content=b"x" * (limit + 1), headers={"content-type": "application/json"})
    assert_problem(r, 413, str(limit))

    def chunks():  # no Content-Length: the limit applies while streaming
        for _ in range(40):
            yield b" " * 65536

    r = api.a.post("/motions", content=chunks(), headers={"content-type": "application/json"})
    assert_problem(r, 413)
    assert api.anon.get("/health").status_code == 200  # the server is fine


def test_multipart_trial_errors_are_422(api):
    r = api.a.post("/motions", files={"files": ("walk.exe", b"MZ...")})
    assert r.status_code in (422, 501)
    if r.status_code == 422:
        assert "unsupported file type" in r.json()["detail"]
    r = api.a.post("/motions", files={"files": ("walk.c3d", b"\x00\x01")}, data={"mass": "nan"})
    assert_problem(r, 422, "mass")
    r = api.a.post("/motions", data={"mass": "70"}, files={"other": ("x.txt", b"")})
    assert_problem(r, 422, "other")


# --- jobs: validation, idempotency, cancel ----------------------------------------------------


@pytest.mark.parametrize(
    "body, needle",
    [
        ({"target": {"slope_deg": 95}}, "slope_deg"),
        ({"target": {"slope_deg": -89}}, "slope_deg"),
        ({"target": {"curve_deg": 1000}}, "curve_deg"),
        ({"target": {"friction": 0}}, "friction"),
        ({"target": {"gravity": -9.81}}, "gravity"),
        ({"target": {}}, "changes nothing"),
        ({"target": {"slope_deg": 3}, "control": {"eps": 0.1, "delta0": 0.05}}, "eps"),
        ({"target": {"slope_deg": 3}, "control": {"method": "newton"}}, "method"),
        ({"target": {"slope_deg": 3}, "tutor": {"character": "robot"}}, "character"),
        ({"target": {"slope_deg": 3}, "extra": 1}, "extra"),
        ({}, "target"),
    ],
)
def test_impossible_targets_rejected(api, motion_id, body, needle):
    before = api.a.get("/jobs", params={"limit": 1}).json()["total"]
    assert_problem(api.a.post(f"/motions/{motion_id}/extrapolate", json=body), 422, needle)
    assert api.a.get("/jobs", params={"limit": 1}).json()["total"] == before


def test_non_finite_target_rejected(api, motion_id):
    for token in ("NaN", "Infinity", "-Infinity", "1e999"):
        r = api.a.post(f"/motions/{motion_id}/extrapolate", content=f'{{"target": {{"slope_deg": {token}}}}}',
                       headers={"content-type": "application/json"})
        assert_problem(r, 422)


def test_extrapolate_202_location_and_idempotency(api, motion_id):
    body = {"target": {"slope_deg": 4.0}, "control": {"delta0": 0.1}}
    r1 = api.a.post(f"/motions/{motion_id}/extrapolate", json=body, headers={"Idempotency-Key": "retry-1"})
    assert r1.status_code == 202, r1.text
    job = r1.json()
    assert r1.headers["location"] == f"/jobs/{job['id']}" == job["links"]["self"]
    assert job["target"]["slope_deg"] == 4.0 and job["control"]["delta0"] == 0.1
    r2 = api.a.post(f"/motions/{motion_id}/extrapolate", json=body, headers={"Idempotency-Key": "retry-1"})
    assert r2.status_code == 202 and r2.json()["id"] == job["id"] and r2.headers["idempotent-replayed"] == "true"
    r3 = api.a.post(f"/motions/{motion_id}/extrapolate", json={"target": {"slope_deg": 5.0}},
                    headers={"Idempotency-Key": "retry-1"})
    assert_problem(r3, 422, "Idempotency-Key")
    # keys are per API key: the same key from another caller is a different request space
    other = upload(api.b, halfboy_motion().to_dict()).json()["id"]
    r4 = api.b.post(f"/motions/{other}/extrapolate", json=body, headers={"Idempotency-Key": "retry-1"})
    assert r4.status_code == 202 and r4.json()["id"] != job["id"]
    # the replayed key read back is the first request's job, with its own target (not the refused 5.0)
    got = api.a.get(f"/jobs/{job['id']}").json()
    assert got["id"] == job["id"] and got["target"]["slope_deg"] == 4.0
    page = api.a.get(f"/jobs/{job['id']}/motions").json()
    assert len(page["items"]) == min(page["total"], page["limit"])
    assert all(m["job_id"] == job["id"] for m in page["items"])


def test_unknown_ids_are_404_problems(api):
    assert_problem(api.a.get("/jobs/j_nope"), 404, "j_nope")
    assert_problem(api.a.get("/motions/m_nope"), 404)
    assert_problem(api.a.post("/motions/m_nope/extrapolate", json={"target": {"slope_deg": 2}}), 404)
    assert_problem(api.a.post("/jobs/j_nope/cancel"), 404)


def test_pagination_params_validated(api, motion_id):
    assert_problem(api.a.get("/motions", params={"limit": 0}), 422, "limit")
    assert_problem(api.a.get("/motions", params={"offset": -1}), 422)
    page = api.a.get("/motions", params={"limit": 1}).json()
    assert len(page["items"]) == 1 and (page["next"] is not None) == (page["total"] > 1)


# --- property-based: any non-finite number or ragged frame anywhere -> 422, never 5xx -----

non_finite = st.sampled_from(["NaN", "Infinity", "-Infinity", "1e400", "-1e999"])


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(row=st.integers(0, 11), col=st.integers(0, 15), token=non_finite)
def test_hypothesis_non_finite_anywhere(api, row, col, token):
    d = halfboy_motion().to_dict()
    d["frames"][row][col] = "@@"
    r = upload(api.a, json.dumps(d).replace('"@@"', token))
    assert_problem(r, 422)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(row=st.integers(0, 11), width=st.integers(0, 40).filter(lambda w: w != 16))
def test_hypothesis_wrong_shapes(api, row, width):
    d = halfboy_motion().to_dict()
    d["frames"][row] = [0.0] * width
    assert_problem(upload(api.a, d), 422, f"frames[{row}] has {width} values")


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.text(st.characters(codec="utf-8"), min_size=1, max_size=30))
def test_hypothesis_unknown_joints(api, name):
    d = halfboy_motion().to_dict()
    if name in d["coordinates"]:
        return
    d["coordinates"][7] = name
    r = upload(api.a, d)
    assert_problem(r, 422)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(target=st.fixed_dictionaries({}, optional={
    "slope_deg": st.floats(allow_nan=False, allow_infinity=False),
    "curve_deg": st.floats(allow_nan=False, allow_infinity=False),
    "friction": st.one_of(st.none(), st.floats(allow_nan=False, allow_infinity=False)),
    "gravity": st.one_of(st.none(), st.floats(allow_nan=False, allow_infinity=False)),
}))
def test_hypothesis_targets_valid_or_422(api, motion_id, target):
    r = api.a.post(f"/motions/{motion_id}/extrapolate", json={"target": target},
                   headers={"Idempotency-Key": "h-" + json.dumps(target, sort_keys=True)[:200].replace(" ", "")})
    ok = (-89 < target.get("slope_deg", 0) < 89 and -720 <= target.get("curve_deg", 0) <= 720
          and (target.get("friction") is None or 0 < target["friction"] <= 10)
          and (target.get("gravity") is None or 0 < target["gravity"] <= 100)
          and any(target.get(k) not in (None, 0, 0.0) for k in target))
    if ok:
        assert r.status_code == 202, r.text
        api.a.post(f"/jobs/{r.json()['id']}/cancel")
    else:
        assert_problem(r, 422)
    assert not math.isnan(r.elapsed.total_seconds())


def test_validation_report_with_mujoco_replay(api):
    r = upload(api.a, halfboy_motion(seed=9).to_dict())
    mid = r.json()["id"]
    rep = api.a.get(f"/motions/{mid}/validation")
    assert rep.status_code == 200, rep.text
    body = rep.json()
    assert body["plausible"] is False  # random coordinates and no contact wrenches
    assert "mujoco_replay" in body and body["checks"]["mujoco_root"] is False
    assert api.a.get(f"/motions/{mid}").json()["format"] == "motionx.clip"
    info = api.a.get("/motions", params={"limit": 1000}).json()["items"]
    assert [m["plausible"] for m in info if m["id"] == mid] == [False]  # the report is stored with the motion
    assert api.a.get(f"/motions/{mid}/validation").json() == body


def test_multipart_mocap_upload_deepmimic(api, shared_data):
    d = shared_data / "deepmimic_humanoid3d_walk"
    files = [("files", (p.name, p.read_bytes())) for p in (d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt")]
    r = api.a.post("/motions", files=files, data={"name": "deepmimic walk"})
    assert r.status_code == 201, r.text
    info = r.json()
    assert (info["kind"], info["name"], info["has_wrenches"]) == ("capture", "deepmimic walk", False)
    assert info["frames"] > 20 and info["coordinates"] > 16
    mf = api.a.get(info["links"]["motion_file"]).json()
    assert mf["provenance"]["step"] == "capture"
    # what the input looks like: mass, stance intervals per foot, fit error (no plates: no implied mass)
    inp = info["input"]
    assert inp["format"] == "deepmimic" and inp["mass_kg"] == 45.0 and "mass_implied_kg" not in inp
    assert inp["stances"]["right"] and inp["stances"]["left"] and inp["landmark_fit_error_mm"]["max"] < 1.0


def test_multipart_upload_reports_plates_mass_and_names_the_mass_field(api, shared_data):
    d = shared_data / "opensim_gait2354_subject01_treadmill"
    names = ("subject01.osim", "subject01_walk1_ik.mot", "subject01_walk1_grf.mot", "subject01_walk1_grf.xml")
    files = [("files", (n, (d / n).read_bytes())) for n in names]
    r = api.a.post("/motions", files=files, data={"belt_speed": "1.13", "mass": "62"})
    assert r.status_code == 201, r.text
    inp = r.json()["input"]
    assert inp["mass_kg"] == 62.0 and abs(inp["mass_implied_kg"] - 72.6) < 0.8
    assert "differs from the 72.7 kg the force plates imply" in inp["mass_warning"]
    bvh = [("files", ("walk.bvh", (shared_data / "cmu16_bvh" / "16_15_walk.bvh").read_bytes()))]
    assert_problem(api.a.post("/motions", files=bvh), 422, "send the form field 'mass'")


def test_multipart_mocap_upload_bad_trials(api, shared_data):
    d = shared_data / "deepmimic_humanoid3d_walk"
    one = [("files", ("humanoid3d_walk.txt", (d / "humanoid3d_walk.txt").read_bytes()))]
    assert_problem(api.a.post("/motions", files=one), 422, "DeepMimic")
    junk = [("files", ("trial.c3d", b"\x02\x50" + b"\x00" * 600))]
    assert_problem(api.a.post("/motions", files=junk, data={"mass": "60"}), 422, "could not import")
    osim_only = [("files", ("model.osim", b"<OpenSimDocument/>"))]
    assert_problem(api.a.post("/motions", files=osim_only), 422)
