"""Whatever a client sends gets a 4xx, never a 5xx, on SQLite and on PostgreSQL alike; the
work a request can cause is bounded by the method's limits (service.limits); responses carry
the security headers. Each case below is something a reliability probe of the service sent;
the API runs as `motionx serve` over HTTP, once per database."""

from __future__ import annotations

import json
import secrets

import httpx
import numpy as np
import pytest
from conftest import start_api_process
from svc_util import halfboy_motion

from service import limits
from service.topology import create_postgres_database, drop_postgres_database

PROBLEM = "application/problem+json"


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def api(request, tmp_path_factory):
    env = {}
    name = None
    if request.param == "postgresql":
        admin = request.getfixturevalue("pg_admin")
        name = f"motionx_hardening_{secrets.token_hex(4)}"
        env["DATABASE_URL"] = create_postgres_database(admin, name, exist_ok=False)
    a = start_api_process(tmp_path_factory.mktemp(f"hardening-{request.param}"), env)
    yield a
    a.close()
    a.proc.stop()
    if name:
        drop_postgres_database(request.getfixturevalue("pg_admin"), name)


def problem(r: httpx.Response, *statuses: int, needle: str = "") -> dict:
    assert r.status_code in statuses, (r.status_code, r.text[:500])
    assert r.headers["content-type"].startswith(PROBLEM), r.headers
    body = r.json()
    assert len(body["detail"]) <= 600, "the detail must not echo the input"
    assert needle in body["detail"], (needle, body["detail"])
    return body


def upload(client, body: dict | str | bytes, **kw) -> httpx.Response:
    content = body if isinstance(body, (str, bytes)) else json.dumps(body)
    return client.post("/motions", content=content, headers={"content-type": "application/json"}, **kw)


def count(api) -> int:
    return api.a.get("/motions", params={"limit": 1}).json()["total"]


def with_wrenches(T: int, fps: float = 15.0):
    from solver.motion import Motion

    m = halfboy_motion(T)
    return Motion(character=m.character, fps=fps, q=m.q, reference_name="halfboy",
                  contacts=np.ones((len(m.character.contacts), T), bool), wrenches=np.zeros((2, 6, T)))


# --- ids, names, paths ----------------------------------------------------------------------

BAD_IDS = ["%00", "m_%00", "a%00b", "m_" + "0" * 300, "x" * 5000, "%C3%A9t%C3%A9", "m_0123456789abcdef0123456789ABCDEF"]


@pytest.mark.parametrize("path", [
    "/motions/{}", "/motions/{}/validation", "/motions/{}/plots/grf.png", "/motions/{}/plots/residuals.png",
    "/motions/{}/plots/filmstrip.png",
    "/jobs/{}", "/jobs/{}/motions", "/jobs/{}/events", "/jobs/{}/plots/progress.png",
])
def test_malformed_ids_are_404_not_database_errors(api, path):
    for ident in BAD_IDS:
        problem(api.a.get(path.format(ident)), 404)
    for ident in BAD_IDS[:3]:
        problem(api.a.post(f"/motions/{ident}/extrapolate", json={"target": {"slope_deg": 2}}), 404)
        problem(api.a.post(f"/jobs/{ident}/cancel"), 404)


def test_names_with_nul_or_too_long_are_422(api):
    body = halfboy_motion().to_json()
    before = count(api)
    problem(upload(api.a, body, params={"name": "a\x00b"}), 422, needle="name")
    problem(upload(api.a, body, params={"name": "n" * 201}), 422, needle="name")
    files = {"files": ("walk.bvh", b"HIERARCHY\n")}
    problem(api.a.post("/motions", files=files, data={"name": "a\x00b"}), 422, needle="name")
    problem(api.a.post("/motions", files=files, data={"name": "n" * 201}), 422, needle="name")
    from solver.character import character_to_dict, reference

    for bad in ("c" * 201, "a\x00b", "tab\there"):
        d = halfboy_motion().to_dict()
        cd = character_to_dict(reference("halfboy"))
        cd["name"] = bad
        d["character"] = {"definition": cd}
        problem(upload(api.a, d), 422, needle="character name")
    assert count(api) == before
    ok = upload(api.a, body, params={"name": "été walk, 1.2 m/s"})
    assert ok.status_code == 201 and ok.json()["name"] == "été walk, 1.2 m/s"


def test_static_paths_with_nul_are_404(api):
    for path in ("/ui/%00.js", "/ui/a%00b/app.js", "/ui/vendor/three/build/%00", "/docs/static/%00",
                 "/ui/" + "x" * 5000 + ".js"):
        problem(api.anon.get(path), 404)


# --- bodies ---------------------------------------------------------------------------------


def test_deeply_nested_json_and_huge_integers_are_refused(api):
    before = count(api)
    for depth in (100, 2_000, 100_000):
        problem(upload(api.a, "[" * depth + "]" * depth), 422, needle="nests too deeply")
    deep_provenance = halfboy_motion().to_dict()
    deep_provenance["provenance"] = {"source": json.loads("[" * 500 + "]" * 500)}
    problem(upload(api.a, deep_provenance), 422, needle="nests too deeply")
    problem(upload(api.a, '{"format": ' + "1" * 5000 + "}"), 422, needle="digits")
    huge_fps = halfboy_motion().to_json().replace('"fps":15.0', '"fps":' + "9" * 400)
    problem(upload(api.a, huge_fps), 422)
    assert count(api) == before
    mid = upload(api.a, halfboy_motion().to_json()).json()["id"]
    for body in ('{"target": {"slope_deg": ' + "1" * 5000 + "}}", "[" * 100_000 + "]" * 100_000,
                 '{"target": ' * 2000 + "1" + "}" * 2000):
        r = api.a.post(f"/motions/{mid}/extrapolate", content=body, headers={"content-type": "application/json"})
        problem(r, 400, 422)
    assert api.anon.get("/health").json()["status"] == "ok"


def test_numbers_are_strict(api):
    mid = upload(api.a, halfboy_motion().to_json()).json()["id"]
    for target in ({"slope_deg": True}, {"slope_deg": "5"}, {"friction": "0.5"}, {"gravity": False}):
        problem(api.a.post(f"/motions/{mid}/extrapolate", json={"target": target}), 422,
                needle="valid number")
    problem(api.a.post(f"/motions/{mid}/extrapolate", json={"target": {"slope_deg": 2}, "control": {"max_iter": 5.0}}),
            422, needle="valid integer")
    problem(api.a.post(f"/motions/{mid}/extrapolate", json={"target": {"slope_deg": 2}, "control": {"max_iter": True}}),
            422, needle="valid integer")
    assert api.a.get("/jobs", params={"limit": 1}).json()["total"] == 0


# --- physically absurd values: refused at upload, never a 500 later -----------------------------


def _character_definition(mutate):
    from solver.character import character_to_dict, reference

    d = halfboy_motion().to_dict()
    cd = character_to_dict(reference("halfboy"))
    mutate(cd)
    d["character"] = {"definition": cd}
    return d


@pytest.mark.parametrize("mutate, needle", [
    (lambda d: d["frames"][0].__setitem__(0, 1e308), "root_tx"),
    (lambda d: d["frames"][3].__setitem__(7, 1e6), "outside the physical range"),
    (lambda d: d.__setitem__("fps", 1e-300), "fps"),
    (lambda d: d.__setitem__("fps", 1e300), "fps"),
    (lambda d: d.update(_character_definition(lambda cd: cd["segments"][3].__setitem__("mass", 0.0))), "mass"),
    (lambda d: d.update(_character_definition(lambda cd: cd["segments"][3].__setitem__("mass", 1e9))), "mass"),
    (lambda d: d.update(_character_definition(
        lambda cd: cd["segments"][3].__setitem__("inertia", [[-1, 0, 0], [0, -1, 0], [0, 0, -1]]))), "inertia"),
    (lambda d: d.update(_character_definition(
        lambda cd: cd["segments"][3].__setitem__("inertia", [[1, 0, 0], [0, 1, 0], [0, 0, 5]]))), "triangle"),
    (lambda d: d.update(_character_definition(lambda cd: cd["segments"][2].__setitem__("offset", [1e300, 0, 0]))),
     "offset"),
], ids=["root_tx-1e308", "hinge-1e6", "fps-1e-300", "fps-1e300", "zero-mass", "huge-mass", "negative-inertia",
        "not-a-rigid-body", "offset-1e300"])
def test_absurd_values_refused_at_upload(api, mutate, needle):
    before = count(api)
    d = halfboy_motion().to_dict()
    mutate(d)
    problem(upload(api.a, d), 422, needle=needle)
    assert count(api) == before


def test_absurd_wrenches_refused(api):
    d = with_wrenches(12).to_dict()
    d["wrenches"]["feet"]["left"][2][5] = 1e12
    problem(upload(api.a, d), 422, needle="force")


def test_deepmimic_with_an_absurd_time_step_is_refused(api, shared_data):
    src = shared_data / "deepmimic_humanoid3d_walk"
    motion = json.loads((src / "humanoid3d_walk.txt").read_text())
    for frame in motion["Frames"]:
        frame[0] = 1e300
    files = [("files", ("humanoid3d_walk.txt", json.dumps(motion).encode())),
             ("files", ("humanoid3d_character.txt", (src / "humanoid3d_character.txt").read_bytes()))]
    body = problem(api.a.post("/motions", files=files), 422)
    assert "/tmp" not in body["detail"] and "motionx-upload" not in body["detail"]  # no server path


def test_a_good_capture_exports_everywhere(api, shared_data):
    """The other side of the checks above: a real trial passes them, and every format of it
    exports (in the compute processes)."""
    from svc_util import deepmimic_files

    up = api.a.post("/motions", files=deepmimic_files(shared_data))
    assert up.status_code == 201, up.text
    mid = up.json()["id"]
    prov = api.a.get(f"/motions/{mid}", params={"format": "motion"}).json()["provenance"]
    assert "motionx-upload" not in json.dumps(prov)  # the server's temporary folder is not stored
    for fmt in ("json", "gltf", "bvh"):
        assert api.a.get(f"/motions/{mid}", params={"format": fmt}).status_code == 200, fmt
    assert api.a.get(f"/motions/{mid}/validation").status_code == 200


# --- limits: what one request may cost ----------------------------------------------------------


def test_an_oversized_motion_is_refused_quickly_without_echo(api):
    """The probe uploaded 98,992 frames (201 Created; a job then took 17.7 GB): over the limit,
    the upload is refused by its size before the schema is even validated."""
    T = limits.MAX_CAPTURE_FRAMES + 1
    d = halfboy_motion().to_dict()
    d["frames"] = [[0] * 16] * T
    body = json.dumps(d, separators=(",", ":"))
    assert len(body) < 2 * 1024 * 1024  # under the test API's body limit
    r = upload(api.a, body)
    problem(r, 422, needle=f"at most {limits.MAX_CAPTURE_FRAMES} frames")
    assert r.elapsed.total_seconds() < 10
    long = halfboy_motion(T=int(limits.MAX_CAPTURE_S * 15) + 2)  # 120 s at 15 fps, plus a frame
    problem(upload(api.a, long.to_json()), 422, needle=f"at most {limits.MAX_CAPTURE_S:g} s")


def test_an_oversized_trial_is_refused_before_its_import(api, shared_data):
    """The probe's 90,000-frame DeepMimic trial cost 238 s of API CPU: the frames a text trial
    declares are checked before the import (whose cost grows with them)."""
    bvh = (shared_data / "cmu16_bvh" / "16_15_walk.bvh").read_bytes()
    huge = bvh.replace(b"Frames:\t117", b"Frames:\t100000")
    assert huge != bvh
    r = api.a.post("/motions", files={"files": ("walk.bvh", huge)}, data={"mass": "70"})
    problem(r, 422, needle=f"at most {limits.MAX_CAPTURE_FRAMES} frames")
    assert r.elapsed.total_seconds() < 5
    slow = bvh.replace(b"Frame Time:\t0.0333333", b"Frame Time:\t2.0")
    problem(api.a.post("/motions", files={"files": ("walk.bvh", slow)}, data={"mass": "70"}), 422,
            needle=f"at most {limits.MAX_CAPTURE_S:g} s")


def test_a_tutor_longer_than_a_gait_cycle_is_refused(api):
    ok = upload(api.a, with_wrenches(limits.MAX_TUTOR_FRAMES, fps=30.0).to_json())
    assert ok.status_code == 201 and ok.json()["kind"] == "motion"
    for T in (limits.MAX_TUTOR_FRAMES + 1, 2000):  # 2,000 frames: the probe's 13-minute tutor
        r = upload(api.a, with_wrenches(T, fps=30.0).to_json())
        assert r.status_code == 201 and r.json()["kind"] == "motion"  # a motion it may store and export...
        before = api.a.get("/jobs", params={"limit": 1}).json()["total"]
        body = problem(api.a.post(f"/motions/{r.json()['id']}/extrapolate", json={"target": {"slope_deg": 2}}),
                       422, needle=f"at most {limits.MAX_TUTOR_FRAMES} frames")  # ...but not a tutor
        assert "gait cycle" in body["detail"] and body["type"].endswith("/limit")
        assert api.a.get("/jobs", params={"limit": 1}).json()["total"] == before
    slow = upload(api.a, with_wrenches(70, fps=15.0).to_json()).json()["id"]  # 4.6 s at 15 fps
    problem(api.a.post(f"/motions/{slow}/extrapolate", json={"target": {"slope_deg": 2}}), 422,
            needle=f"{limits.MAX_TUTOR_S:g} s")
    capture = upload(api.a, halfboy_motion().to_json()).json()["id"]
    problem(api.a.post(f"/motions/{capture}/extrapolate", json={"target": {"slope_deg": 2}, "tutor": {"fps": 60}}),
            422, needle="tutor.fps")


def test_limits_name_the_limit():
    with pytest.raises(limits.LimitError, match="at most 128 coordinates"):
        limits.check_motion(frames=10, fps=30, coordinates=129, segments=10, contacts=4)
    with pytest.raises(limits.LimitError, match="at most 128 segments"):
        limits.check_motion(frames=10, fps=30, coordinates=10, segments=129, contacts=4)
    with pytest.raises(limits.LimitError, match="at most 64 coordinates"):
        limits.check_tutor(frames=30, fps=30, coordinates=65)
    limits.check_tutor(frames=121, fps=30, coordinates=64)
    limits.check_motion(frames=30_000, fps=250, coordinates=128, segments=128, contacts=32)
    assert limits.json_depth_ok([[[1]]], limit=3) and not limits.json_depth_ok([[[[1]]]], limit=3)


# --- methods and headers ----------------------------------------------------------------------


def test_options_and_405_list_every_method(api):
    r = api.a.options("/motions")
    assert r.status_code == 204 and r.headers["allow"] == "GET, POST"
    r = api.a.delete("/motions")
    assert r.status_code == 405 and r.headers["allow"] == "GET, POST"
    problem(r, 405, needle="GET, POST")
    mid = "m_" + "0" * 32
    assert api.a.options(f"/motions/{mid}").headers["allow"] == "GET, DELETE"
    assert api.a.options(f"/motions/{mid}/extrapolate").headers["allow"] == "POST"
    assert api.a.put("/health").headers["allow"] == "GET"


def test_security_headers(api):
    for path in ("/ui/", "/docs", "/health", "/openapi.json", "/motions"):
        r = api.anon.get(path)
        assert r.headers["x-content-type-options"] == "nosniff", path
        assert r.headers["x-frame-options"] == "DENY", path
        assert "frame-ancestors 'none'" in r.headers["content-security-policy"], path
    page = api.anon.get("/ui/").headers["content-security-policy"]
    assert "script-src 'self' 'sha256-" in page and "unsafe" not in page  # the import map, by its hash
    assert api.anon.get("/health").headers["content-security-policy"].startswith("default-src 'none'")
