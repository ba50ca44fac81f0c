"""The page without traps, in headless Chromium against ``motionx serve``:

- a failed upload clears its files, so the next files are a trial of their own (not refused as
  a mix of formats with the failed ones); an upload that only lacks a field (the mass) keeps them;
- Start says which walk it runs on, and nothing is chosen for the user: with motions stored and
  none uploaded from the form, Start asks for one;
- one download button per distinct file (no "glTF" and "GLB" for one .glb), DeepMimic and OpenSim
  offered only for motions that can have them (a motion from an OpenSim trial gets OpenSim);
- a motion without a skeleton of its own says its downloads are on its character;
- an OpenSim trial is previewed on its model's bodies (gait2354's pelvis, femurs, tibias…).

(The simulated walk framed with the motion: tests/service/test_web_simulation.py; the rig box on
a DeepMimic walk's optimum: tests/service/test_web_workflow.py.) About 30 s.
"""

from __future__ import annotations

import pytest
import test_web_page
from svc_util import KEY_A, halfboy_motion
from test_web_page import SCREENSHOT, _missing, _open, _orange, _pixels, _state, viewer, wait_js

from service.routes.web import THREE_DIR

browser = test_web_page.browser
tutor_id = test_web_page.tutor_id


@pytest.fixture(scope="module")
def page(api, browser, tutor_id):
    """The page with the key in its URL, once the tutor (a stored motion) is listed."""
    if not THREE_DIR.is_dir():
        _missing("three.js is not installed: run `npm ci` in service/web")
    context, page, _requests, errors = _open(browser, 1400, 1100)
    page.goto(f"{api.base_url}/ui/#key={KEY_A}")
    page.wait_for_selector("#key-status.ok")
    page.wait_for_selector(f'#motion-list button[data-id="{tutor_id}"]')
    page.errors = errors
    yield page
    context.close()


def _buttons(page) -> list[str]:
    return page.eval_on_selector_all("#download-buttons button", "bs => bs.map(b => b.dataset.format)")


def test_start_says_which_walk_it_runs_on(page, tutor_id):
    wait_js(page, "document.querySelectorAll('#source-select option').length > 1")
    assert page.eval_on_selector("#source-select", "s => s.value") == ""  # no silent preselection
    assert "Choose the walk to start from" in page.text_content("#source-note")
    page.fill("#target-slope_deg", "5")
    page.click("#start-button")
    wait_js(page, "window.motionx.state.startStatus === 'error'")
    assert "choose the walk to start from" in page.text_content("#start-status")
    page.select_option("#source-select", tutor_id)
    note = page.text_content("#source-note")
    assert note.startswith("Start runs on DeepMimic walk tutor") and tutor_id[:10] in note, note
    assert page.text_content("#start-button") == "Start on DeepMimic walk tutor"
    assert _state(page)["startSource"] == tutor_id


def test_a_failed_upload_clears_its_files(api, page, shared_data, tmp_path):
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")  # not a BVH file the importer can read
    page.set_input_files("#trial-files", str(bad))
    page.fill("#opt-mass", "70")
    page.click("#upload-button")
    wait_js(page, "window.motionx.state.uploadStatus === 'error'", timeout=60)
    said = page.text_content("#upload-status")
    assert "the files were cleared" in said, said
    assert page.locator("#trial-list li").count() == 0 and _state(page)["trialFiles"] == []
    page.eval_on_selector("#opt-mass", "i => { i.value = ''; }")  # back among the options, hidden
    # the next trial goes in: not refused as a mix of .bvh and .txt files
    walk = shared_data / "deepmimic_humanoid3d_walk"
    page.set_input_files("#trial-files", [str(walk / "humanoid3d_walk.txt"), str(walk / "humanoid3d_character.txt")])
    assert _state(page)["trialFiles"] == ["humanoid3d_walk.txt", "humanoid3d_character.txt"]
    page.click("#upload-button")
    wait_js(page, "window.motionx.state.uploadStatus === 'ok'", timeout=60)
    uploaded = _state(page)["uploadedId"]
    assert page.eval_on_selector("#source-select", "s => s.value") == uploaded  # the walk just uploaded, said so
    assert page.text_content("#source-note").startswith("Start runs on ")
    assert not page.errors, page.errors


def test_one_button_per_file_and_only_the_formats_a_motion_can_have(api, page, tutor_id, shared_data):
    page.click(f'#motion-list button[data-id="{tutor_id}"]')
    wait_js(page, f"(s => s.motionId === '{tutor_id}' && s.exports !== null)(window.motionx.state)", timeout=60)
    got = _buttons(page)
    assert "glb" not in got and got.count("gltf") == 1, got  # one .glb, one button
    labels = page.eval_on_selector_all("#download-buttons button", "bs => bs.map(b => b.textContent)")
    assert len(set(labels)) == len(labels) and "glTF (.glb)" in labels, labels
    assert "deepmimic" in got and "opensim" not in got, got  # a DeepMimic walk's tutor: no OpenSim
    assert page.locator("#download-rig-box").is_visible()

    # a motion without a rig of its own: neither DeepMimic nor OpenSim, and it says where its files go
    r = api.a.post("/motions?name=synthetic", content=halfboy_motion().to_json(),
                   headers={"Content-Type": "application/json"})
    assert r.status_code == 201, r.text
    plain = r.json()["id"]
    page.evaluate(f"window.motionx.selectMotion('{plain}')")
    wait_js(page, f"(s => s.motionId === '{plain}' && s.exports !== null)(window.motionx.state)", timeout=60)
    assert _buttons(page) == ["json", "gltf", "bvh", "motion"], _buttons(page)
    assert not page.locator("#download-rig-box").is_visible()
    assert "has no skeleton of its own" in page.text_content("#download-rig-none")

    # a motion from an OpenSim trial gets its OpenSim (zip) button
    t = shared_data / "opensim_gait2354_subject01_treadmill"
    files = [("files", (n, (t / n).read_bytes())) for n in ("subject01.osim", "subject01_walk1_ik.mot")]
    r = api.a.post("/motions", files=files, data={"belt_speed": "1.13", "name": "treadmill"})
    assert r.status_code == 201, r.text
    osim = r.json()["id"]
    assert api.a.get(f"/motions/{osim}/exports").json()["rig"] == "opensim"
    page.evaluate(f"window.motionx.selectMotion('{osim}')")
    wait_js(page, f"(s => s.motionId === '{osim}' && s.exports !== null)(window.motionx.state)", timeout=60)
    assert "opensim" in _buttons(page) and "deepmimic" not in _buttons(page), _buttons(page)

    # and is previewed on its model's bodies (pelvis, femurs, tibias… of gait2354), not on blobs of our character
    wait_js(page, f"(s => s.motionId === '{osim}' && (s.previewReady || s.previewError))(window.motionx.state)",
            timeout=90)
    s = _state(page)
    assert s["previewReady"] and s["previewRig"] == "source", s
    assert page.text_content("#viewer-rig") == "on its OpenSim model's bodies"
    names = page.evaluate("(() => { const n = []; window.motionx.viewer.model.traverse((o) => n.push(o.name));"
                          " return n; })()")
    assert {"pelvis", "femur_r", "tibia_l", "calcn_r", "torso"} <= set(names), names
    viewer(page, "v.setPlaying(false)")
    img = _pixels(page.locator("#viewer-canvas").screenshot())
    viewer(page, "v.setPlaying(true)")
    assert _orange(img) > 0.003 * img.shape[0] * img.shape[1], "the model's bodies are not drawn"
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    page.locator("#viewer-canvas").screenshot(path=str(SCREENSHOT.with_name("opensim_model.png")))
    assert not page.errors, page.errors
