"""The web page (``GET /ui/``) in headless Chromium, on a real job.

The API runs as its own process (``motionx serve``), a real tutor is uploaded and a real
extrapolation job (``CHEAP``) runs. The page is opened with the key in the URL fragment and
driven like a user: select the job (its progress curve must be drawn), select a λ optimum
(its character must be rendered by three.js, its GRF plot loaded, its plausibility report
shown). Pixels are checked from screenshots of the canvases.

Chromium is Debian's ``chromium`` driven by the Python ``playwright`` package with
``executable_path`` (never ``playwright install``). Without it the browser tests skip,
unless ``MOTIONX_REQUIRE_BROWSER=1`` (CI), where they fail.
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
from pathlib import Path
from urllib.parse import urljoin, urlparse

import numpy as np
import pytest
from conftest import start_api_process
from svc_util import CHEAP, KEY_A, halfboy_motion, wait_job

from service.routes.web import STATIC_DIR, THREE_DIR
from solver.motion import Motion

REPO = Path(__file__).resolve().parents[2]
SCREENSHOT = REPO / "out" / "web" / "screenshot.png"
REQUIRE_BROWSER = os.environ.get("MOTIONX_REQUIRE_BROWSER") == "1"
#: WebGL in headless Chromium without a GPU: ANGLE on SwiftShader (software)
CHROMIUM_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"]
PREVIEW_UNAVAILABLE = "3D preview unavailable: run npm ci in service/web"
TIMEOUT_MS = 30_000


def _missing(reason: str):
    if REQUIRE_BROWSER:
        pytest.fail(f"{reason} (MOTIONX_REQUIRE_BROWSER=1)")
    pytest.skip(reason)


def _chromium() -> str | None:
    exe = shutil.which("chromium") or "/usr/bin/chromium"
    return exe if os.access(exe, os.X_OK) else None


@pytest.fixture(scope="module")
def browser():
    exe = _chromium()
    if exe is None:
        _missing("chromium is not installed (apt-get install chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _missing("the playwright package is not installed (pip install -e '.[test]')")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture(scope="module")
def tutor_id(api, tutor_motion_json) -> str:
    """The tutor of the DeepMimic walk (made by the pipeline), uploaded."""
    r = api.a.post("/motions?name=DeepMimic%20walk%20tutor", content=tutor_motion_json,
                   headers={"Content-Type": "application/json"})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def _start_job(api, tutor_id: str) -> str:
    r = api.a.post(f"/motions/{tutor_id}/extrapolate", json=CHEAP)
    assert r.status_code == 202, r.text
    return r.json()["id"]


def _pixels(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def _near(img: np.ndarray, rgb: str, tol: int = 40) -> int:
    """How many pixels are within ``tol`` (per channel) of the colour ``#rrggbb``."""
    target = np.array([int(rgb[i:i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(img - target).max(axis=2) <= tol).sum())


def _orange(img: np.ndarray) -> int:
    """Pixels of the character (CHARACTER_COLOR 0xe07b39, shaded): red well above green above blue."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return int(((r > 110) & (r - g > 35) & (g - b > 20)).sum())


def viewer(page, js: str) -> None:
    """Runs ``js`` with ``v`` = the page's 3D viewer, then waits for a rendered frame."""
    page.evaluate(f"async () => {{ const v = window.motionx.viewer; {js}; await v.nextFrame(); }}")


def _state(page) -> dict:
    return page.evaluate("JSON.parse(JSON.stringify(window.motionx.state))")


def _csp_violation(message, errors: list) -> None:
    """The browser reports what the page's Content-Security-Policy blocked on the console."""
    if message.type == "error" and "Content Security Policy" in message.text:
        errors.append(message.text)


def _open(browser, width: int, height: int):
    """A new context and page; the requests it makes, and its errors (uncaught exceptions and
    Content-Security-Policy violations)."""
    context = browser.new_context(viewport={"width": width, "height": height})
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    requests, errors = [], []
    page.on("request", lambda req: requests.append(req.url))
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("console", lambda m: _csp_violation(m, errors))
    return context, page, requests, errors


def wait_js(page, expression: str, timeout: float = 30.0) -> None:
    """Polls ``expression`` until it is truthy. (``page.wait_for_function`` evaluates its
    predicate with eval in the page, which the page's Content-Security-Policy forbids;
    ``page.evaluate`` goes through the DevTools protocol.)"""
    import time

    deadline = time.monotonic() + timeout
    while not page.evaluate(expression):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {expression}")
        time.sleep(0.1)


# ------------------------------------------------------------------ without a browser

def test_page_and_vendor_files_are_served_locally(api):
    r = api.anon.get("/", follow_redirects=False)
    assert r.status_code in (302, 307) and r.headers["location"].endswith("/ui/")
    page = api.anon.get("/ui/")  # public: no key needed for the page itself
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert api.anon.get("/motions").status_code == 401  # ... but the API still wants one

    html = page.text
    imports = json.loads(re.search(r'<script type="importmap">(.*?)</script>', html, re.DOTALL).group(1))["imports"]
    assert set(imports) == {"three", "three/addons/"}
    if not THREE_DIR.is_dir():
        r = api.anon.get(urljoin("/ui/", imports["three"]))
        assert r.status_code == 404 and "npm ci" in r.json()["detail"]
        _missing("three.js is not installed: run `npm ci` in service/web")
    for url in (imports["three"], "./vendor/three/build/three.core.js",
                imports["three/addons/"] + "loaders/GLTFLoader.js",
                imports["three/addons/"] + "controls/OrbitControls.js", "app.js", "progress.js", "preview.js",
                "newwalk.js"):
        r = api.anon.get(urljoin("/ui/", url))
        assert r.status_code == 200, (url, r.status_code)
        assert r.headers["content-type"].split(";")[0] == "text/javascript", (url, r.headers["content-type"])
    assert api.anon.get("/ui/style.css").headers["content-type"].startswith("text/css")
    # only what the page needs from node_modules, and nothing outside it
    for url in ("/ui/vendor/three/package.json", "/ui/vendor/three/build/three.cjs", "/ui/vendor/three/src/Three.js",
                "/ui/vendor/three/examples/jsm/..%2F..%2Fsrc%2FThree.js",
                "/ui/..%2Fnode_modules%2Fthree%2Fsrc%2FThree.js", "/ui/nope.js"):
        assert api.anon.get(url).status_code == 404, url

    # no CDN or other host: no absolute http(s) URL in our own files
    for path in sorted(STATIC_DIR.iterdir()):
        found = re.findall(r"https?://[^\s'\"<>)]+", path.read_text())
        assert not found, f"{path.name} refers to another host: {found}"
    # and none of it in the API's OpenAPI document
    assert not [p for p in api.anon.get("/openapi.json").json()["paths"] if p == "/" or p.startswith("/ui")]


# ------------------------------------------------------------------ in headless Chromium

def test_page_shows_progress_and_renders_the_character(api, browser, tutor_id):
    if not THREE_DIR.is_dir():
        _missing("three.js is not installed: run `npm ci` in service/web")
    context, page, requests, errors = _open(browser, 1400, 1000)
    try:
        page.goto(f"{api.base_url}/ui/#key={KEY_A}")
        assert "key=" not in page.url  # taken from the fragment, then out of the address bar
        page.wait_for_selector("#key-status.ok")  # the page's module has run (it stores the key first)
        assert page.evaluate("localStorage.getItem('motionx.apiKey')") == KEY_A

        # a job started while the page is open: the list shows it, its progress curve is drawn
        job_id = _start_job(api, tutor_id)
        page.click(f'#job-list button[data-id="{job_id}"]')
        job = wait_job(api.a, job_id, timeout=60)
        assert job["status"] == "succeeded", job
        wait_js(page, f"window.motionx.state.jobStatus === 'succeeded' && "
                               f"window.motionx.state.progressPoints === {len(job['progress'])} && "
                               f"window.motionx.state.jobMotions.length === {job['steps']}")
        assert page.text_content("#job-status") == "succeeded"
        curve = _pixels(page.locator("#progress-canvas").screenshot())
        assert _near(curve, "#2f6fb0") > 30 * len(job["progress"]), "accepted solves not drawn"
        assert _near(curve, "#2e7d4f") > 100, "λ-reached staircase not drawn"

        # its last λ optimum: 3D preview, GRF plot, plausibility report
        last = page.locator("#job-motions button").last
        assert last.text_content().startswith("λ = 1")
        last.click()
        wait_js(page, "(s => s.previewReady && (s.grfLoaded || s.grfError) && s.validation)"
                               "(window.motionx.state)")
        state = _state(page)
        assert state["previewError"] is None and state["grfError"] is None, state
        assert page.evaluate("document.getElementById('grf-img').naturalWidth") > 0
        table = page.text_content("#validation")
        assert "plausible" in table and "not plausible" not in table, table
        assert state["validation"]["plausible"] is True
        # the naturalness verdict and checks, each with the captured walk's own figure where it has one
        assert "natural" in table and "not natural" not in table and "swing clearance" in table, table
        assert state["validation"]["natural"] is True and "(capture " in table
        wait_js(page, "window.motionx.state.filmstripLoaded || window.motionx.state.filmstripError")
        assert _state(page)["filmstripError"] is None
        assert page.evaluate("document.getElementById('filmstrip-img').naturalWidth") > 800

        # the character, paused: present when shown, gone when hidden
        canvas = page.locator("#viewer-canvas")
        viewer(page, "v.setPlaying(false)")
        shown = _pixels(canvas.screenshot())
        viewer(page, "v.setCharacterVisible(false)")
        hidden = _pixels(canvas.screenshot())
        viewer(page, "v.setCharacterVisible(true); v.setPlaying(true)")
        assert len(np.unique(shown.reshape(-1, 3), axis=0)) > 200, "3D canvas looks empty"
        assert _orange(shown) > 0.01 * shown.shape[0] * shown.shape[1], "no character pixels"
        assert _orange(hidden) < 0.0005 * hidden.shape[0] * hidden.shape[1]
        changed = (np.abs(shown - hidden).max(axis=2) > 30).sum()
        assert changed > 0.01 * shown.shape[0] * shown.shape[1], "hiding the character changes nothing"
        assert hidden.std() > 2, "no ground grid"

        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        wait_js(page, "window.motionx.state.residualsLoaded || window.motionx.state.residualsError")
        page.screenshot(path=str(SCREENSHOT), full_page=True)

        # everything came from the API's own host
        foreign = [u for u in requests if not u.startswith((api.base_url + "/", "blob:", "data:"))]
        assert not foreign, foreign
        assert not errors, errors
        assert not _state(page)["errors"]
    finally:
        context.close()


def test_page_draws_the_stairs_treads_under_a_stairs_motion(api, browser, tutor_id):
    """A stairs optimum (terrain axis) is previewed standing on its treads: the GLB's own ground
    (node "ground": a tread per stance and the risers between them), its levels the heights of
    the plausibility report's treads (motionx z = glTF y), the world not tilted."""
    if not THREE_DIR.is_dir():
        _missing("three.js is not installed: run `npm ci` in service/web")
    r = api.a.post(f"/motions/{tutor_id}/extrapolate",
                   json={"target": {"step_height_m": 0.1}, "control": {"delta0": 0.5}})
    assert r.status_code == 202, r.text
    job = wait_job(api.a, r.json()["id"], timeout=120)
    assert job["status"] == "succeeded", job
    context, page, _, errors = _open(browser, 1200, 900)
    try:
        page.goto(f"{api.base_url}/ui/#key={KEY_A}")
        page.wait_for_selector("#key-status.ok")
        page.click(f'#job-list button[data-id="{job["id"]}"]')
        wait_js(page, f"window.motionx.state.jobMotions.length === {job['steps']}", timeout=60)
        page.locator("#job-motions button").last.click()
        wait_js(page, "(s => s.previewReady && s.validation)(window.motionx.state)", timeout=60)
        treads = _state(page)["validation"]["environment"]["treads"]
        drawn = page.evaluate("(() => { const g = window.motionx.viewer.ground; if (!g) return null; const ys = "
                              "new Set(); g.traverse(o => { if (o.isMesh) { const p = o.geometry.attributes.position;"
                              " for (let i = 0; i < p.count; i += 1) ys.add(Math.round(p.getY(i) * 1e4) / 1e4); } });"
                              " return [...ys].sort((a, b) => a - b); })()")
        heights = sorted({round(t["center"][2], 4) for t in treads})
        assert drawn is not None and len(heights) >= 3, (drawn, treads)
        assert drawn == pytest.approx(heights, abs=2e-4)  # every level is a tread's top (float32)
        assert max(drawn) - min(drawn) == pytest.approx(0.1 * (len(heights) - 1), abs=2e-4)
        assert page.evaluate("window.motionx.viewer.world.quaternion.w") == 1.0  # the file is in its world
        assert page.evaluate("window.motionx.viewer.treads") is None  # no boxes of the page's own
        assert not errors, errors
    finally:
        context.close()


def test_page_without_three_says_so_and_keeps_working(api, browser, tutor_id):
    """What a pip install without ``npm ci`` looks like: no vendor files, the rest works.
    And a raw capture (no contact wrenches) has no GRF plot: the page says why."""
    job_id = _start_job(api, tutor_id)
    capture = api.a.post("/motions?name=raw%20capture", content=halfboy_motion().to_json(),
                         headers={"Content-Type": "application/json"})
    assert capture.status_code == 201 and capture.json()["kind"] == "capture", capture.text
    assert wait_job(api.a, job_id, timeout=60)["status"] == "succeeded"
    context = browser.new_context(viewport={"width": 1200, "height": 900})
    context.route("**/ui/vendor/**", lambda route: route.fulfill(
        status=404, content_type="application/problem+json",
        body=json.dumps({"title": "Not Found", "status": 404, "detail": "three.js is not installed"})))
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("console", lambda m: _csp_violation(m, errors))
    try:
        page.goto(f"{api.base_url}/ui/")
        page.fill("#key-input", KEY_A)
        page.click("#key-form button[type=submit]")
        page.click(f'#job-list button[data-id="{job_id}"]')
        wait_js(page, "window.motionx.state.jobMotions.length > 0 && window.motionx.state.progressPoints > 0")
        page.locator("#job-motions button").first.click()
        wait_js(page, "(s => s.previewError && s.validation && (s.grfLoaded || s.grfError))"
                               "(window.motionx.state)")
        assert _state(page)["previewError"] == PREVIEW_UNAVAILABLE
        assert page.locator("#viewer-message").is_visible()
        assert page.text_content("#viewer-message") == PREVIEW_UNAVAILABLE
        assert _state(page)["grfLoaded"]
        assert "plausible" in page.text_content("#validation")

        page.click(f'#motion-list button[data-id="{capture.json()["id"]}"]')
        wait_js(page, "(s => s.grfError && s.validation)(window.motionx.state)")
        assert api.a.get(f"/motions/{capture.json()['id']}/plots/grf.png").status_code // 100 == 4
        assert page.locator("#grf-message").is_visible() and not page.locator("#grf-img").is_visible()
        assert page.text_content("#grf-message") == f"No plot: {_state(page)['grfError']}"
        assert "not plausible" in page.text_content("#validation")
        assert not errors, errors
    finally:
        context.close()


def test_a_key_entered_while_the_page_starts_is_kept(api, browser, tutor_id):
    """The page starts with the stored key (none here) once GET /axes has answered. A key a
    user enters before that answer is theirs: the start must not put the empty key back (on a
    loaded server /axes answered after the key was submitted, the lists went empty and the job
    never showed)."""
    job_id = _start_job(api, tutor_id)
    assert wait_job(api.a, job_id, timeout=60)["status"] == "succeeded"
    context = browser.new_context(viewport={"width": 1200, "height": 900})
    held = []
    context.route("**/axes", lambda route: held.append(route))  # answered below, after the key
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    try:
        page.goto(f"{api.base_url}/ui/")
        for _ in range(200):
            if held:
                break
            page.wait_for_timeout(50)
        assert held, "the page did not ask for /axes"
        page.fill("#key-input", KEY_A)
        page.click("#key-form button[type=submit]")
        page.wait_for_selector(f'#job-list button[data-id="{job_id}"]')
        with page.expect_response("**/axes"):
            held[0].continue_()
        page.wait_for_timeout(500)  # the start's late useKey(stored key) would have emptied the lists by now
        state = _state(page)
        assert state["keyStatus"] == "ok" and any(j["id"] == job_id for j in state["jobs"]), state["keyStatus"]
        page.click(f'#job-list button[data-id="{job_id}"]')
        wait_js(page, "window.motionx.state.jobStatus === 'succeeded'")
    finally:
        context.close()


def test_docs_page_is_swagger_ui_from_local_files(api, browser):
    """/docs: Swagger UI from swagger-ui-dist (npm), every request to the API's own host, no
    Content-Security-Policy violation, and the operations of the OpenAPI document listed."""
    r = api.anon.get("/docs")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    for h in ("content-security-policy", "x-content-type-options", "x-frame-options"):
        assert h in r.headers, h
    assert "script-src 'self'" in r.headers["content-security-policy"]
    assert not re.findall(r"https?://", r.text)  # no CDN
    if not (STATIC_DIR.parent / "node_modules" / "swagger-ui-dist").is_dir():
        assert "npm ci" in r.text
        _missing("swagger-ui-dist is not installed: run `npm ci` in service/web")
    for f in ("swagger-ui-bundle.js", "swagger-ui.css"):
        assert api.anon.get(f"/docs/static/{f}").status_code == 200
    assert api.anon.get("/docs/static/package.json").status_code == 404
    context, page, requests, errors = _open(browser, 1200, 900)
    try:
        page.goto(f"{api.base_url}/docs")
        wait_js(page, "document.querySelectorAll('.opblock').length >= 10")
        text = page.text_content("#swagger-ui")
        assert "/motions/{motion_id}/extrapolate" in text and "motionx" in text
        assert not errors, errors
        hosts = {urlparse(u).netloc for u in requests if urlparse(u).scheme in ("http", "https")}
        assert hosts == {urlparse(api.base_url).netloc}, hosts
    finally:
        context.close()


def test_page_shows_a_library_grid_and_previews_a_cell(api, browser, tutor_id):
    """A 2 x 2 library: the grid as a heat map of status (every cell green once done), the
    overall progress, and a cell's clip (its last realistic λ optimum) walking in the 3D preview."""
    if not THREE_DIR.is_dir():
        _missing("three.js is not installed: run `npm ci` in service/web")
    grid = {"slope_deg": [-5.0, 5.0], "curve_deg": [-20.0, 20.0]}
    r = api.a.post(f"/motions/{tutor_id}/library", json={"grid": grid})
    assert r.status_code == 202, r.text
    lid = r.json()["id"]
    context, page, requests, errors = _open(browser, 1400, 1000)
    try:
        page.goto(f"{api.base_url}/ui/#key={KEY_A}")
        page.wait_for_selector(f'#library-list button[data-id="{lid}"]')
        page.click(f'#library-list button[data-id="{lid}"]')
        wait_js(page, "window.motionx.state.libraryCells === 4", timeout=30)
        wait_js(page, "window.motionx.state.libraryStatus === 'succeeded'", timeout=180)
        lib = api.a.get(f"/libraries/{lid}").json()
        assert lib["status"] == "succeeded"
        # the grid: rows slope, columns curve, a button per cell with its status
        heads = page.locator("#library-grid th").all_text_contents()
        assert "slope -5°" in heads and "curve 20°" in heads, heads
        assert sorted(page.locator("#library-grid button").evaluate_all("bs => bs.map(b => b.dataset.status)")) == \
            ["succeeded"] * 4
        assert page.text_content("#library-facts").count("4 of 4 done") == 1
        grid = _pixels(page.locator("#library-grid").screenshot())
        assert _near(grid, "#2e7d4f", tol=20) > 400, "succeeded cells are not drawn green"
        # a cell's clip walks in the 3D preview
        page.click('#library-grid button[data-key="slope5_curve20"]')
        wait_js(page, "(s => s.cellKey === 'slope5_curve20' && s.previewReady)(window.motionx.state)", timeout=60)
        cell = next(c for c in lib["cells"] if c["key"] == "slope5_curve20")
        last = api.a.get(f"/jobs/{cell['job_id']}/motions?limit=100").json()["items"][-1]
        assert _state(page)["motionId"] == last["id"]
        shown = _pixels(page.locator("#viewer-canvas").screenshot())
        assert _orange(shown) > 0.01 * shown.shape[0] * shown.shape[1], "no character pixels"
        page.screenshot(path=str(SCREENSHOT.with_name("library.png")), full_page=True)
        assert not errors, errors
        assert not _state(page)["errors"]
    finally:
        context.close()


#: a check section from outside the project, in one module: the walk's mean speed, a warning
SPEED_CHECK = '''
"""The walk's mean speed over the clip (a check section registered from outside motionx)."""
import numpy as np

from solver.checks import Check, SectionResult, register_check


@register_check(section="walking_speed", verdict="natural", order=25, title="walking speed (added)")
def walking_speed(ctx):
    m = ctx.motion
    speed = float(np.linalg.norm(m.q[:2, -1] - m.q[:2, 0]) * m.fps / (m.T - 1))
    return SectionResult((Check.measure("mean_speed", speed, 0.3, "m/s", "root travel over the clip's duration",
                                        warning=True, at_least=True),), {"frames": m.T})
'''


def test_a_check_section_added_in_one_module_reaches_the_report_and_the_page(tmp_path_factory, browser,
                                                                              tutor_motion_json):
    """A module that registers a check section, named in MOTIONX_CHECK_MODULES: its section is in
    the API's validation report (computed in a compute process) and rendered on the page, with no
    other edit."""
    plugins = tmp_path_factory.mktemp("plugins")
    (plugins / "speed_check.py").write_text(SPEED_CHECK)
    path = os.pathsep.join(p for p in (str(plugins), os.environ.get("PYTHONPATH", "")) if p)
    a = start_api_process(tmp_path_factory.mktemp("api_plugin"), {"MOTIONX_CHECK_MODULES": "speed_check",
                                                                  "PYTHONPATH": path})
    try:
        r = a.a.post("/motions?name=tutor", content=tutor_motion_json, headers={"Content-Type": "application/json"})
        assert r.status_code == 201, r.text
        motion_id = r.json()["id"]
        rep = a.a.get(f"/motions/{motion_id}/validation", timeout=120).json()
        names = [s["name"] for s in rep["sections"]]
        assert names == ["residual", "contacts", "realism", "naturalness", "walking_speed", "mujoco_replay"], names
        check = rep["walking_speed"]["checks"]["mean_speed"]
        m = Motion.from_dict(json.loads(tutor_motion_json))
        q = m.q
        assert check["value"] == pytest.approx(np.linalg.norm(q[:2, -1] - q[:2, 0]) * m.fps / (q.shape[1] - 1))
        assert check["passed"] and 0.8 < check["value"] < 2.0 and rep["walking_speed"]["frames"] == q.shape[1]

        context, page, _requests, errors = _open(browser, 1200, 900)
        try:
            page.goto(f"{a.base_url}/ui/#key={KEY_A}")
            try:
                page.wait_for_selector(f'#motion-list button[data-id="{motion_id}"]', timeout=90_000)
            except Exception as e:  # say what the page saw (a CI run timed out here once)
                seen = page.evaluate("JSON.stringify(window.motionx && window.motionx.state)")
                log = (a.data_dir / "api.log").read_text()
                raise AssertionError(f"the uploaded motion is not listed: {e}; page state {seen[:2000]}; "
                                     f"errors {errors}; API log {log[-3000:]}") from e
            page.click(f'#motion-list button[data-id="{motion_id}"]')
            wait_js(page, "window.motionx.state.validation", timeout=60)
            section = page.locator('#validation tr[data-section="walking_speed"]')
            assert section.text_content().startswith("walking speed (added)")
            row = page.locator('#validation tr[data-check="mean_speed"]')
            assert row.text_content().startswith("mean speed (m/s)") and "≥ 0.3" in row.text_content()
            assert row.locator("td").last.text_content() == "✓"
            assert not errors, errors
        finally:
            context.close()
    finally:
        a.close()
        a.proc.stop()


def test_a_check_module_that_cannot_be_found_stops_the_server_naming_it(tmp_path):
    """A misspelt module in MOTIONX_CHECK_MODULES is refused at start, named (not a compute
    process failing on every request)."""
    with pytest.raises(Exception) as e:
        start_api_process(tmp_path, {"MOTIONX_CHECK_MODULES": "no_such_check_module"})
    log = (tmp_path / "api.log").read_text()
    assert "no_such_check_module" in log and "not importable" in log, (str(e.value), log[-2000:])
