"""The plot endpoints over HTTP (uvicorn, SQLite, local runner): a real job's progress curve,
a tutor's and a λ optimum's GRF and residual plots; ownership, unknown ids, raw captures."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from svc_util import CHEAP, halfboy_motion, wait_job

PROBLEM = "application/problem+json"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def assert_png_response(r) -> tuple[int, int]:
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "image/png"
    assert r.content[:8] == PNG_SIGNATURE
    img = Image.open(io.BytesIO(r.content))
    img.load()
    px = np.asarray(img.convert("RGB"), dtype=float)
    assert 500 <= img.size[0] <= 3000 and 300 <= img.size[1] <= 3000, img.size
    assert px.std() > 10.0 and (px.min(axis=2) < 200).mean() > 0.01  # something is drawn
    return img.size


def assert_problem(r, status: int, needle: str = "") -> None:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith(PROBLEM)
    assert needle in r.json()["detail"]


@pytest.fixture(scope="module")
def tutor_id(api, tutor_motion_json) -> str:
    r = api.a.post("/motions", content=tutor_motion_json, headers={"Content-Type": "application/json"})
    assert r.status_code == 201, r.text
    assert r.json()["kind"] == "motion" and r.json()["has_wrenches"]
    return r.json()["id"]


@pytest.fixture(scope="module")
def capture_id(api) -> str:
    r = api.a.post("/motions", json=halfboy_motion().to_dict())
    assert r.status_code == 201, r.text
    assert r.json()["kind"] == "capture" and not r.json()["has_wrenches"]
    return r.json()["id"]


@pytest.fixture(scope="module")
def finished_job(api, tutor_id) -> dict:
    r = api.a.post(f"/motions/{tutor_id}/extrapolate", json=CHEAP)
    assert r.status_code == 202, r.text
    job = wait_job(api.a, r.json()["id"], timeout=120)
    assert job["status"] == "succeeded", job
    return job


def test_progress_plot_of_a_job(api, finished_job):
    job = finished_job
    assert any(p["accepted"] for p in job["progress"])
    first = api.a.get(f"/jobs/{job['id']}/plots/progress.png")
    assert_png_response(first)
    assert api.a.get(f"/jobs/{job['id']}/plots/progress.png").content == first.content


def test_grf_and_residual_plots_of_the_tutor_and_the_last_optimum(api, tutor_id, finished_job):
    items = api.a.get(f"/jobs/{finished_job['id']}/motions").json()["items"]
    last = items[-1]
    assert last["lam"] == 1.0
    for mid in (tutor_id, last["id"]):
        for name in ("grf", "residuals", "filmstrip"):
            assert_png_response(api.a.get(f"/motions/{mid}/plots/{name}.png"))


def test_a_motion_without_wrenches_gets_422_but_its_filmstrip(api, capture_id):
    for name in ("grf", "residuals"):
        assert_problem(api.a.get(f"/motions/{capture_id}/plots/{name}.png"), 422, "no contact wrenches")
    assert_png_response(api.a.get(f"/motions/{capture_id}/plots/filmstrip.png"))


def test_other_keys_and_unknown_ids_get_404(api, tutor_id, capture_id, finished_job):
    job = finished_job["id"]
    for path in (f"/jobs/{job}/plots/progress.png", f"/motions/{tutor_id}/plots/grf.png",
                 f"/motions/{tutor_id}/plots/residuals.png", f"/motions/{capture_id}/plots/grf.png"):
        assert_problem(api.b.get(path), 404, "or it belongs to another API key")
        assert_problem(api.anon.get(path), 401, "API key")
    for path in ("/jobs/job_nope/plots/progress.png", "/motions/mot_nope/plots/grf.png",
                 "/motions/mot_nope/plots/residuals.png"):
        assert_problem(api.a.get(path), 404, "nope")
    assert api.a.get(f"/motions/{tutor_id}/plots/cop.png").status_code == 404


def test_openapi_documents_the_png_routes(api):
    doc = api.anon.get("/openapi.json").json()
    for path in ("/jobs/{job_id}/plots/progress.png", "/motions/{motion_id}/plots/grf.png",
                 "/motions/{motion_id}/plots/residuals.png", "/motions/{motion_id}/plots/filmstrip.png"):
        op = doc["paths"][path]["get"]
        assert list(op["responses"]["200"]["content"]) == ["image/png"]
        assert "404" in op["responses"]
