"""Results on the user's own rig over HTTP: an uploaded DeepMimic walk's λ optima download as a
DeepMimic motion for the same character (``format=deepmimic``), and an uploaded BVH walk's as a
BVH on the input's own skeleton (``format=bvh&rig=source``); what cannot be done is a 422 that
says why."""

from __future__ import annotations

import json

from svc_util import CHEAP, deepmimic_files, wait_job

from solver.io.bvh import parse_bvh, read_bvh


def _last_optimum(c, files, data=None) -> str:
    up = c.post("/motions", files=files, data=data or {})
    assert up.status_code == 201, up.text
    job = c.post(f"/motions/{up.json()['id']}/extrapolate", json=CHEAP)
    assert job.status_code == 202, job.text
    done = wait_job(c, job.json()["id"], timeout=300)
    assert done["status"] == "succeeded", done
    items = c.get(f"/jobs/{done['id']}/motions", params={"limit": 100}).json()["items"]
    return items[-1]["id"]


def test_deepmimic_upload_downloads_on_its_character(api, shared_data):
    mid = _last_optimum(api.a, deepmimic_files(shared_data))
    r = api.a.get(f"/motions/{mid}", params={"format": "deepmimic"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("application/json")
    d = json.loads(r.content)
    assert d["Loop"] == "wrap" and len(d["Frames"][0]) == 44  # humanoid3d's frame layout
    r = api.a.get(f"/motions/{mid}", params={"format": "bvh", "rig": "source"})
    assert r.status_code == 422 and "deepmimic" in r.text


def test_bvh_upload_downloads_on_its_rig(api, shared_data):
    path = shared_data / "cmu16_bvh" / "16_15_walk.bvh"
    mid = _last_optimum(api.a, {"files": (path.name, path.read_bytes())}, {"mass": "70"})
    r = api.a.get(f"/motions/{mid}", params={"format": "bvh", "rig": "source"})
    assert r.status_code == 200, r.text
    out, src = parse_bvh(r.text), read_bvh(path)
    assert out.names == src.names and out.parents == src.parents and out.channels == src.channels
    r = api.a.get(f"/motions/{mid}", params={"format": "deepmimic"})
    assert r.status_code == 422 and "bvh" in r.text
