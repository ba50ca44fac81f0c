"""The whole path through the web page (``GET /ui/``) in headless Chromium: the page's own file
input and buttons, against ``motionx serve`` running real jobs.

- the DeepMimic walk (motion + character files; the mass is in the character file) is uploaded
  through the page's ``<input type=file>``, a job is started from its form (HalfBoy at 15 fps,
  slope 5°, Δ0 = 0.5: the job makes the tutor, then two λ steps), followed on the page's progress
  display to ``succeeded``; its last λ optimum is previewed by three.js on the walk's own DeepMimic
  rig (``rig=source``), and downloads from the page's buttons are valid GLB, BVH, JSON clip and
  DeepMimic files (Playwright's download event); OpenSim, which needs an OpenSim trial, says why;
- a second job, long on purpose (Δ0 = 1e-4), is canceled from the page while it runs, and so is a
  library of two cells started from the same form (a grid of slopes);
- a BVH walk (no subject mass in BVH files): the form shows the mass field up front, the API's 422
  is shown when it is left empty, and the upload with a mass goes through;
- a motion file without a rig of its own is previewed on its character (the fallback).

Chromium is Debian's ``chromium`` driven by Playwright (as in ``test_web_page.py``). About 100 s
on this 2-core machine, most of it the job's tutor.
"""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest
import test_web_page
from svc_util import KEY_A, halfboy_motion, wait_job
from test_web_page import SCREENSHOT, _missing, _open, _orange, _pixels, _state, viewer, wait_js

from service.routes.web import THREE_DIR

browser = test_web_page.browser  # the module's Chromium (Debian's, driven by Playwright)
JOB_TIMEOUT_S = 240.0  # the tutor (~10-20 s) and two steps; generous for a loaded CI machine


@pytest.fixture(scope="module")
def page(api, browser):
    """One page for the module, with the key entered in its own form."""
    if not THREE_DIR.is_dir():
        _missing("three.js is not installed: run `npm ci` in service/web")
    context, page, requests, errors = _open(browser, 1400, 1100)
    page.goto(f"{api.base_url}/ui/")
    # the form is built from the OpenAPI document (public), its targets from GET /axes (with the key)
    wait_js(page, "document.querySelectorAll('#download-buttons button').length > 0")
    assert page.locator("#new-walk-key").is_visible()  # no key yet: the form says where to get one
    assert page.locator("#target-fields input").count() == 0
    page.fill("#key-input", KEY_A)
    page.click("#key-form button[type=submit]")
    page.wait_for_selector("#key-status.ok")
    wait_js(page, "document.querySelectorAll('#target-fields input').length > 0")
    assert not page.locator("#new-walk-key").is_visible()
    page.requests, page.errors = requests, errors
    yield page
    context.close()


def _glb(data: bytes) -> dict:
    """The JSON chunk of a binary glTF, after checking its header (magic, version 2, length)."""
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and length == len(data), (magic, version, length, len(data))
    chunk_len, chunk_type = struct.unpack_from("<I4s", data, 12)
    assert chunk_type == b"JSON"
    return json.loads(data[20:20 + chunk_len])


def _bvh_offsets(text: str) -> np.ndarray:
    """Every OFFSET of a BVH hierarchy (its bone lengths, in the file's unit)."""
    return np.array([[float(x) for x in line.split()[1:4]] for line in text.splitlines()
                     if line.strip().startswith("OFFSET")])


def _download(page, fmt: str):
    """Clicks the page's download button of ``fmt``: (file name, bytes)."""
    with page.expect_download(timeout=60_000) as info:
        page.click(f'#download-buttons button[data-format="{fmt}"]')
    d = info.value
    wait_js(page, "window.motionx.state.downloadStatus === 'ok'", timeout=10)
    return d.suggested_filename, open(d.path(), "rb").read()


def test_upload_start_follow_preview_download_and_cancel(api, page, shared_data):
    walk = shared_data / "deepmimic_humanoid3d_walk"
    state = lambda: _state(page)  # noqa: E731

    # 1. the trial through the page's own file input: two files, the mass stated by the character file
    page.set_input_files("#trial-files", [str(walk / "humanoid3d_walk.txt"), str(walk / "humanoid3d_character.txt")])
    assert page.locator("#trial-list li").count() == 2
    assert not state()["massRequired"] and not page.locator("#mass-why").is_visible()
    page.fill("#trial-name", "DeepMimic walk")
    page.click("#upload-button")
    wait_js(page, "window.motionx.state.uploadStatus === 'ok'", timeout=60)
    uploaded = state()["uploadedId"]
    motion = api.a.get("/motions?limit=100").json()["items"][-1]
    assert motion["id"] == uploaded and motion["kind"] == "capture" and motion["name"] == "DeepMimic walk"
    facts = page.text_content("#upload-facts")
    assert "deepmimic" in facts and "45 kg (character file)" in facts, facts
    assert page.locator("#trial-list li").count() == 0  # uploaded: the selection is cleared
    assert page.eval_on_selector("#source-select", "s => s.value") == uploaded

    # 2. the tutor and a small target, from controls built from GET /axes and the OpenAPI document
    tutor_in = api.anon.get("/openapi.json").json()["components"]["schemas"]["TutorIn"]["properties"]["character"]
    chars = next(b["enum"] for b in tutor_in["anyOf"] if "enum" in b)  # optional: the service's default first
    assert page.eval_on_selector_all("#tutor-character option", "os => os.map(o => o.value)") == ["", *chars]
    axes = [a["name"] for a in api.a.get("/axes").json()["axes"]]
    assert page.eval_on_selector_all("#target-fields input", "is => is.map(i => i.name)") == axes
    page.select_option("#tutor-character", "halfboy")
    page.fill("#tutor-fps", "15")
    page.fill("#target-slope_deg", "5")
    page.click("#control-options summary")
    page.fill("#control-delta0", "0.5")
    page.click("#start-button")
    wait_js(page, "window.motionx.state.startStatus === 'ok'")
    job_id = state()["startedId"]
    assert state()["jobId"] == job_id

    # 3. followed on the page until it ends (the SSE stream): status, progress curve, environment reached
    wait_js(page, "document.getElementById('job-status').textContent === 'succeeded'", timeout=JOB_TIMEOUT_S)
    job = api.a.get(f"/jobs/{job_id}").json()
    assert job["status"] == "succeeded" and job["target"]["slope_deg"] == 5.0 and job["motion_id"] == uploaded
    assert job["tutor_motion_id"] is not None  # the job made the capture's tutor first
    wait_js(page, f"window.motionx.state.progressPoints === {len(job['progress'])}")
    assert state()["environmentReached"]["slope_deg"] == pytest.approx(5.0)
    assert "slope 5°" in page.text_content("#job-facts")

    # 4. its last λ optimum previewed by itself, on the DeepMimic walk's own rig
    optima = api.a.get(f"/jobs/{job_id}/motions?limit=100").json()["items"]
    assert optima[-1]["lam"] == 1.0
    wait_js(page, f"(s => s.motionId === '{optima[-1]['id']}' && s.previewReady)(window.motionx.state)", timeout=60)
    s = state()
    assert s["previewRig"] == "source" and s["previewError"] is None, s
    rig_glb = _glb(api.a.get(f"/motions/{optima[-1]['id']}", params={"format": "glb", "rig": "source"}).content)
    assert s["previewObjects"] >= len(rig_glb["nodes"]) > 0
    assert page.text_content("#viewer-rig") == "on the input's own rig"
    # a 5° slope is tilted once: the GLB walks up its ramp (its node "ground") in an untilted world
    tilt = page.evaluate("(v => [v.world.quaternion.w, v.groundNormal.y, v.ground ? v.ground.name : null])"
                         "(window.motionx.viewer)")
    assert tilt[0] == 1.0 and tilt[2] == "ground", tilt
    assert math.degrees(math.acos(tilt[1])) == pytest.approx(5.0, abs=1e-3), tilt
    viewer(page, "v.setPlaying(false)")
    shown = _pixels(page.locator("#viewer-canvas").screenshot())
    viewer(page, "v.setPlaying(true)")
    assert _orange(shown) > 0.005 * shown.shape[0] * shown.shape[1], "no character pixels"

    # 5. downloads from the page's buttons: one per distinct file the motion can be (GET /motions/{id}/exports)
    wait_js(page, "window.motionx.state.exports !== null")
    exports = api.a.get(f"/motions/{optima[-1]['id']}/exports").json()
    assert exports["rig"] == "deepmimic" and exports["on_rig"] == ["gltf", "deepmimic"], exports
    assert page.eval_on_selector_all("#download-buttons button", "bs => bs.map(b => b.dataset.format)") == \
        [*exports["formats"], "motion"]
    assert "its DeepMimic character" in page.text_content("#download-rig-box")
    name, data = _download(page, "gltf")  # on the rig: the DeepMimic skeleton's joints
    assert name == f"{optima[-1]['id']}.rig.glb"
    gltf = _glb(data)
    assert gltf["animations"] and {"root", "right_knee", "left_ankle"} <= {n.get("name") for n in gltf["nodes"]}
    name, data = _download(page, "bvh")  # rig=source is for BVH trials: the motion's own HalfBoy skeleton, said so
    said = page.text_content("#download-status")
    assert name == f"{optima[-1]['id']}.bvh" and "BVH is not written on its DeepMimic character" in said, said
    text = data.decode()
    assert text.startswith("HIERARCHY") and "\nMOTION\n" in text
    assert int(text.split("Frames:")[1].split()[0]) == optima[-1]["frames"]
    page.fill("#download-options", "units=m")  # an exporter option (docs/export.md), passed through
    _, data = _download(page, "bvh")
    assert _bvh_offsets(data.decode()) == pytest.approx(_bvh_offsets(text) / 100, abs=1e-4)
    page.fill("#download-options", "units")
    page.click('#download-buttons button[data-format="bvh"]')
    wait_js(page, "window.motionx.state.downloadStatus === 'error'")
    assert "is not NAME=VALUE" in page.text_content("#download-status")
    page.fill("#download-options", "")
    name, data = _download(page, "json")
    assert name == f"{optima[-1]['id']}.clip.json" and json.loads(data)
    name, data = _download(page, "deepmimic")
    frames = json.loads(data)["Frames"]
    assert name.endswith(".rig.deepmimic.json") and len(frames[0]) == 44  # humanoid3d's frame layout
    # OpenSim needs an OpenSim trial: not offered for this motion (tests/service/test_web_traps.py)
    assert page.locator('#download-buttons button[data-format="opensim"]').count() == 0

    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOT.with_name("workflow.png")), full_page=True)

    # 6. a second job, long on purpose (the stored tutor, then λ steps from 1e-4), canceled from the page
    page.fill("#control-delta0", "0.0001")
    page.fill("#control-eps", "0.0001")
    page.click("#start-button")
    wait_js(page, f"window.motionx.state.startedId !== '{job_id}' && window.motionx.state.startStatus === 'ok'")
    second = state()["startedId"]
    wait_js(page, "window.motionx.state.jobStatus === 'running' && window.motionx.state.progressPoints >= 2",
            timeout=JOB_TIMEOUT_S)
    page.click("#job-cancel")
    wait_js(page, "document.getElementById('job-cancel').textContent === 'Canceling…' || "
                  "document.getElementById('job-status').textContent === 'canceled'")  # the API took it
    assert api.a.get(f"/jobs/{second}").json()["cancel_requested"]
    wait_js(page, "document.getElementById('job-status').textContent === 'canceled'", timeout=60)
    done = wait_job(api.a, second, timeout=10)
    assert done["status"] == "canceled" and done["cancel_requested"] and done["lam_reached"] < 1.0, done
    assert not page.locator("#job-cancel").is_visible()

    # 7. a library grid from the same form (slope 3° and 6°, steps still from 1e-4), canceled from the page
    page.check('input[name="start-mode"][value="library"]')
    assert not page.locator("#target-fields").is_visible()
    assert page.eval_on_selector_all("#grid-fields input", "is => is.map(i => i.name)") == \
        [a["name"] for a in api.a.get("/axes").json()["axes"] if a["grid"]]
    page.fill("#grid-slope_deg", "3, 6")
    assert page.text_content("#grid-cells").startswith("2 cells")
    page.click("#start-button")
    wait_js(page, f"window.motionx.state.startedId !== '{second}' && window.motionx.state.startStatus === 'ok'")
    lid = state()["startedId"]
    assert lid.startswith("l_") and state()["libraryId"] == lid
    wait_js(page, "window.motionx.state.libraryCells === 2")
    page.click("#library-cancel")
    wait_js(page, "window.motionx.state.libraryStatus === 'canceled'", timeout=60)
    lib = api.a.get(f"/libraries/{lid}").json()
    assert lib["status"] == "canceled" and lib["grid"] == {"slope_deg": [3.0, 6.0]} and lib["progress"]["canceled"] >= 1
    assert sorted(page.locator("#library-grid button").evaluate_all("bs => bs.map(b => b.dataset.status)")) == \
        sorted(c["status"] for c in lib["cells"])

    assert not page.errors, page.errors
    assert not _state(page)["errors"], _state(page)["errors"]
    foreign = [u for u in page.requests if not u.startswith((api.base_url + "/", "blob:", "data:"))]
    assert not foreign, foreign


def test_a_bvh_upload_asks_for_the_mass(api, page, shared_data):
    """BVH files never state the subject's mass: the field is shown and required as soon as the
    file is dropped on the form; uploading without it shows the API's 422 as it is; with it the
    trial goes in."""
    bvh = shared_data / "cmu16_bvh" / "16_15_walk.bvh"
    # dropped on the drop zone, as a file manager's drag and drop delivers it (a DataTransfer of Files)
    files = page.evaluate_handle("([name, text]) => { const dt = new DataTransfer();"
                                 " dt.items.add(new File([text], name, { type: 'text/plain' })); return dt; }",
                                 [bvh.name, bvh.read_text()])
    page.dispatch_event("#drop-zone", "drop", {"dataTransfer": files})
    s = _state(page)
    assert s["trialFiles"] == ["16_15_walk.bvh"] and s["massRequired"]
    assert page.locator("#mass-slot #opt-mass").is_visible()
    assert page.eval_on_selector("#opt-mass", "i => i.required")
    assert "do not state the subject's mass" in page.text_content("#mass-why")

    page.click("#upload-button")
    wait_js(page, "window.motionx.state.uploadStatus === 'error'", timeout=60)
    said = page.text_content("#upload-status")
    assert "subject mass unknown" in said and "send the form field 'mass'" in said, said
    assert "The API needs the subject's mass" in page.text_content("#mass-why")
    assert page.evaluate("document.activeElement.id") == "opt-mass"

    page.fill("#opt-mass", "70")
    page.click("#upload-button")
    wait_js(page, "window.motionx.state.uploadStatus === 'ok'", timeout=60)
    motion = api.a.get("/motions?limit=100").json()["items"][-1]
    assert motion["id"] == _state(page)["uploadedId"] and motion["kind"] == "capture"
    assert "70 kg (given)" in page.text_content("#upload-facts")
    assert not _state(page)["massRequired"] and page.input_value("#opt-mass") == ""  # ready for the next trial
    assert not page.errors, page.errors


def test_a_motion_without_a_rig_of_its_own_is_previewed_on_its_character(api, page, tmp_path):
    """A motion file (uploaded through the page too) has no input rig: rig=source is a 4xx, and the
    preview falls back to the motion's own HalfBoy."""
    path = tmp_path / "synthetic.json"
    path.write_text(halfboy_motion().to_json())
    page.set_input_files("#trial-files", str(path))
    page.click("#upload-button")
    wait_js(page, "window.motionx.state.uploadStatus === 'ok'", timeout=60)
    mid = _state(page)["uploadedId"]
    assert api.a.get(f"/motions/{mid}", params={"format": "glb", "rig": "source"}).status_code // 100 == 4
    page.click("#upload-facts button")
    wait_js(page, f"(s => s.motionId === '{mid}' && (s.previewReady || s.previewError))(window.motionx.state)",
            timeout=60)
    s = _state(page)
    assert s["previewReady"] and s["previewRig"] == "character", s
    assert page.text_content("#viewer-rig") == "on the halfboy character"
    assert not page.locator("#download-rig-box").is_visible()
    wait_js(page, "window.motionx.state.exports !== null")
    assert "has no skeleton of its own" in page.text_content("#download-rig-none")  # said, not a silent fallback
    assert not page.errors, page.errors
    assert not s["errors"], s["errors"]
