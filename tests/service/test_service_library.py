"""Motion libraries over the real service (`motionx serve`: SQLite + the local process pool, one
job process): a grid fanned out as one job per cell, progress per cell and overall, warm starts
from stored optima, the manifest and the library GLB (three.js), cancel, bad requests."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest
from conftest import start_api_process
from svc_util import TERMINAL

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tests" / "js" / "load_glb.mjs"
THREE = ROOT / "service" / "web" / "node_modules" / "three"
NODE = shutil.which("node")

GRID = {"grid": {"slope_deg": [-5.0, 5.0], "curve_deg": [-20.0, 20.0]}}


@pytest.fixture(scope="module")
def lib_api(tmp_path_factory):
    d = tmp_path_factory.mktemp("library")
    a = start_api_process(d, {"MOTIONX_SWEEP_INTERVAL_S": "1", "MOTIONX_JOB_LEASE_S": "3"})
    yield a
    a.close()
    a.proc.stop()


@pytest.fixture(scope="module")
def tutor_id(lib_api, tutor_motion_json):
    r = lib_api.a.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"})
    assert r.status_code == 201
    return r.json()["id"]


def wait_library(client, lid: str, *, timeout: float, until=None) -> tuple[dict, list[dict]]:
    """Poll until ``until(library)`` (default: a terminal status); returns it and every snapshot."""
    until = until or (lambda lib: lib["status"] in TERMINAL)
    seen, deadline = [], time.monotonic() + timeout
    while True:
        r = client.get(f"/libraries/{lid}")
        assert r.status_code == 200, r.text
        lib = r.json()
        seen.append(lib)
        if until(lib):
            return lib, seen
        assert time.monotonic() < deadline, f"library not done after {timeout} s: {lib['progress']}"
        time.sleep(0.2)


@pytest.fixture(scope="module")
def grid_library(lib_api, tutor_id):
    t0 = time.monotonic()
    r = lib_api.a.post(f"/motions/{tutor_id}/library", json=GRID)
    assert r.status_code == 202, r.text
    assert r.headers["location"] == f"/libraries/{r.json()['id']}"
    lib, seen = wait_library(lib_api.a, r.json()["id"], timeout=300)
    return r.json(), lib, seen, time.monotonic() - t0


def test_grid_library_completes_with_one_job_per_cell(lib_api, grid_library):
    created, lib, seen, wall = grid_library
    assert created["status"] in ("queued", "running") and created["progress"]["cells"] == 4
    assert lib["status"] == "succeeded", lib
    keys = sorted(c["key"] for c in lib["cells"])
    assert keys == ["slope-5_curve-20", "slope-5_curve20", "slope5_curve-20", "slope5_curve20"]
    assert len({c["job_id"] for c in lib["cells"]}) == 4  # one job per cell
    for c in lib["cells"]:
        assert c["status"] == "succeeded" and c["lam_reached"] == 1.0 and c["attempts"] == 1
        job = lib_api.a.get(c["links"]["job"]).json()
        assert job["target"] == c["parameters"]  # the cell's job extrapolates to the cell's target
        steps = lib_api.a.get(f"{c['links']['motions']}?limit=100").json()["items"]
        assert [m["step"] for m in steps] == list(range(job["steps"]))  # every optimum once, in order
        lams = [m["lam"] for m in steps]
        assert lams == sorted(lams) and lams[-1] == 1.0
        # the cell's clip: its last optimum, checked plausible by the job (MuJoCo replay included)
        assert c["clip_motion_id"] == steps[-1]["id"] and c["clip_lam"] == 1.0 and c["plausible"] is True
    p = lib["progress"]
    assert p["done"] == p["succeeded"] == 4 and p["fraction"] == 1.0
    # progress was honest: monotone per cell and overall, never done before every cell was
    fr = [s["progress"]["fraction"] for s in seen]
    assert fr == sorted(fr)
    assert all(s["progress"]["done"] == sum(c["status"] in TERMINAL for c in s["cells"]) for s in seen)
    times = [c["wall_time_s"] for c in lib["cells"]]
    print(f"2x2 library: {wall:.1f} s wall, cell times {times}")


def test_cells_start_from_the_base_optimum_another_cell_solved(lib_api, grid_library):
    _, lib, _, _ = grid_library
    first = [c for c in lib["cells"] if c["job_id"] == min((c["started_at"], c["job_id"]) for c in lib["cells"])[1]]
    warm = 0
    for c in lib["cells"]:
        steps = lib_api.a.get(f"{c['links']['motions']}?limit=1").json()["items"]
        m0 = lib_api.a.get(steps[0]["links"]["motion_file"]).json()
        ws = m0["provenance"].get("warm_start")
        if ws is not None:
            warm += 1
            assert ws["lam"] == 0.0 and ws["source_lam"] == 0.0 and steps[0]["lam"] == 0.0
            assert ws["source_cell"] != c["key"]
            src = lib_api.a.get(f"/jobs/{ws['source_job']}/motions?limit=1").json()["items"][0]
            same = lib_api.a.get(src["links"]["motion_file"]).json()
            assert same["frames"] == m0["frames"] and same["wrenches"] == m0["wrenches"]  # the same optimum
    assert first and warm == 3  # with one job process the cells run one after the other: all but the first


def test_manifest_and_library_glb(lib_api, grid_library, tmp_path):
    _, lib, _, _ = grid_library
    r = lib_api.a.get(lib["links"]["manifest"])
    assert r.status_code == 200
    man = r.json()
    assert man["format"] == "motionx.library" and man["status"] == "succeeded"
    assert man["summary"]["cells"] == man["summary"]["succeeded"] == 4
    for e in man["cells"]:
        assert e["realism"]["plausible"] and e["realism"]["root_residual_rel_weight"] < 1e-6
        assert e["loop"]["seamless"] and e["clip_lambda"] == 1.0
        assert e["cycle"]["slope_deg"] == pytest.approx(e["parameters"]["slope_deg"], abs=1e-6)
        clip = lib_api.a.get(e["files"]["clip"]).json()
        assert clip["game"]["cycle"]["slope_deg"] == pytest.approx(e["parameters"]["slope_deg"], abs=1e-6)
    # turning left (curve +20) turns more to the left than turning right
    turn = {e["key"]: e["cycle"]["turn_rate_deg_s"] for e in man["cells"]}
    assert turn["slope5_curve20"] - turn["slope5_curve-20"] > 20.0
    r = lib_api.a.get(lib["links"]["glb"])
    assert r.status_code == 200 and r.headers["content-type"] == "model/gltf-binary"
    # in the gravity world by default, each cell's ground beside it; world=ground keeps the solver's frame
    doc = json.loads(r.content[20:20 + int.from_bytes(r.content[12:16], "little")])
    assert doc["asset"]["extras"]["world"] == "gravity"
    assert sorted(n["name"] for n in doc["nodes"] if n["name"].startswith("ground ")) == sorted(
        f"ground {c['key']}" for c in lib["cells"])
    flat = lib_api.a.get(lib["links"]["glb"], params={"world": "ground"})
    assert flat.status_code == 200 and flat.content != r.content
    assert json.loads(flat.content[20:20 + int.from_bytes(flat.content[12:16], "little")])["asset"]["extras"][
        "world"] == "ground"
    bad = lib_api.a.get(lib["links"]["glb"], params={"world": "level"})
    assert bad.status_code == 422 and "gravity" in bad.text
    if NODE is None or not THREE.is_dir():
        pytest.skip("node and three.js are needed to load the GLB")
    path = tmp_path / "library.glb"
    path.write_bytes(r.content)
    out = subprocess.run([NODE, str(SCRIPT), str(path), "0", "end"], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "THREE_DIR": str(THREE), "ANIMATIONS": "all"})
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    names = [c["key"] for c in lib["cells"]]
    assert [a["name"] for a in got["animations"]] == names
    assert got["asset"]["extras"]["library"]["id"] == lib["id"]
    from test_game_export import assert_loops_in_three

    assert assert_loops_in_three(got["animation_poses"], got["animation_extras"], names) < 1e-4


def test_a_cell_on_a_solved_cells_ray_starts_part_way(lib_api, tutor_id):
    r = lib_api.a.post(f"/motions/{tutor_id}/library", json={"targets": [{"slope_deg": 5.0}, {"slope_deg": 2.5}]})
    assert r.status_code == 202, r.text
    lib, _ = wait_library(lib_api.a, r.json()["id"], timeout=180)
    assert lib["status"] == "succeeded"
    cells = {c["key"]: c for c in lib["cells"]}
    assert [c["key"] for c in lib["cells"]] == ["slope5", "slope2.5"]  # listed as asked
    outer = lib_api.a.get(f"{cells['slope5']['links']['motions']}?limit=1").json()["items"][0]
    ws = lib_api.a.get(outer["links"]["motion_file"]).json()["provenance"]["warm_start"]
    # slope 2.5 ran first (nearest the tutor); its λ = 1 optimum is slope 5's problem at λ = 0.5
    assert ws["source_cell"] == "slope2.5" and ws["source_lam"] == 1.0 and ws["lam"] == 0.5
    assert outer["lam"] == 0.5 and outer["step"] == 0
    # it saved solves: the inner cell needed the base problem and its own walk, the outer one half a walk
    assert cells["slope5"]["solves"] <= cells["slope2.5"]["solves"]


def test_cancel_stops_every_cell(lib_api, tutor_id):
    body = {"grid": {"slope_deg": [3.0, 6.0, 9.0]}, "control": {"method": "thesis", "delta0": 0.01, "eps": 0.001}}
    r = lib_api.a.post(f"/motions/{tutor_id}/library", json=body)
    lid = r.json()["id"]
    wait_library(lib_api.a, lid, timeout=60, until=lambda lib: lib["progress"]["running"] >= 1)
    c = lib_api.a.post(f"/libraries/{lid}/cancel")
    assert c.status_code == 202 and c.json()["cancel_requested"]
    lib, _ = wait_library(lib_api.a, lid, timeout=120)
    assert lib["status"] == "canceled"
    st = [x["status"] for x in lib["cells"]]
    assert st.count("canceled") >= 2 and all(s in ("canceled", "succeeded") for s in st), st
    assert lib_api.a.post(f"/libraries/{lid}/cancel").status_code == 409  # finished


@pytest.mark.parametrize("body, words", [
    ({"grid": {"speed_scale": [0.8, 3.0]}}, "speed_scale"),  # out of the axis's bounds [0.5, 2]
    ({"grid": {"slope_deg": [5.0, 5.0]}}, "repeats"),
    ({"grid": {"slope_deg": [1.0, 2.0, 3.0, 4.0, 5.0], "curve_deg": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]}, "targets": [{}]},
     "either grid or targets"),
    ({"targets": [{"slope_deg": 5.0}, {"slope_deg": 5.0}]}, "repeats"),
    ({"grid": {"slope_deg": [float(i) for i in range(-12, 13)], "curve_deg": [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]}},
     "at most 125"),
    ({"grid": {}}, "at least one axis"),
])
def test_bad_library_requests_are_clear_422s(lib_api, tutor_id, body, words):
    r = lib_api.a.post(f"/motions/{tutor_id}/library", json=body)
    assert r.status_code == 422, r.text
    assert words in r.text


def test_unknown_ids_and_other_owners_get_404(lib_api, grid_library):
    _, lib, _, _ = grid_library
    assert lib_api.b.get(f"/libraries/{lib['id']}").status_code == 404
    assert lib_api.a.get("/libraries/l_" + "0" * 32).status_code == 404
    assert lib_api.a.get("/libraries/nonsense").status_code == 404
    assert lib_api.a.post("/motions/m_" + "0" * 32 + "/library", json=GRID).status_code == 404
    page = lib_api.a.get("/libraries").json()
    assert lib["id"] in [x["id"] for x in page["items"]]


def test_events_stream_every_cell_until_the_library_ends(lib_api, tutor_id):
    r = lib_api.a.post(f"/motions/{tutor_id}/library", json={"grid": {"curve_deg": [-10.0, 10.0]}})
    lid = r.json()["id"]
    events = []
    with lib_api.a.stream("GET", f"/libraries/{lid}/events", timeout=120) as resp:
        assert resp.headers["content-type"].startswith("text/event-stream")
        ev = None
        for line in resp.iter_lines():
            if line.startswith("event: "):
                ev = line[7:]
            elif line.startswith("data: "):
                events.append((ev, json.loads(line[6:])))
                if ev == "end":
                    break
    kinds = [e for e, _ in events]
    assert kinds[-1] == "end" and events[-1][1]["status"] == "succeeded"
    final = lib_api.a.get(f"/libraries/{lid}").json()
    for c in final["cells"]:  # each cell's last event is its final state
        last = [d for e, d in events if e == "cell" and d["key"] == c["key"]][-1]
        assert last["status"] == "succeeded" and last["lam_reached"] == 1.0
    done = [d["progress"]["done"] for e, d in events if e == "status"]
    assert done == sorted(done) and done[-1] == 2  # overall progress never goes back
    assert lib_api.a.get(f"/libraries/l_{'0' * 32}/events").status_code == 404


def test_a_cell_at_impasse_keeps_its_last_realistic_lambda_and_is_marked(lib_api, tutor_id):
    """Slope 60° with coarse steps (Algorithm 3, Δ0 = 0.25, ε = 0.125): the cell stops at an
    impasse part-way; the library says so, and the cell's clip is its last optimum."""
    body = {"targets": [{"slope_deg": 60.0}], "control": {"method": "thesis", "delta0": 0.25, "eps": 0.125,
                                                            "max_iter": 60}}
    r = lib_api.a.post(f"/motions/{tutor_id}/library", json=body)
    lib, _ = wait_library(lib_api.a, r.json()["id"], timeout=180)
    (cell,) = lib["cells"]
    assert lib["status"] == "impasse" and cell["status"] == "impasse" and cell["at_impasse"]
    assert 0.0 < cell["lam_reached"] < 1.0 and "impasse" in cell["message"]
    (e,) = lib_api.a.get(lib["links"]["manifest"]).json()["cells"]
    assert e["at_impasse"] and e["clip_lambda"] == e["lambda_reached"] == cell["lam_reached"]
    assert e["realism"]["plausible"] and e["cycle"]["slope_deg"] == pytest.approx(60.0 * cell["lam_reached"])
    clip = lib_api.a.get(e["files"]["clip"]).json()
    assert clip["game"]["loop"]["seamless"]
    glb = lib_api.a.get(lib["links"]["glb"])
    assert glb.status_code == 200 and b"slope60" in glb.content[:20000]  # its animation is in the GLB
