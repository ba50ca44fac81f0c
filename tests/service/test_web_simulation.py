"""The page's "Simulate in MuJoCo" (headless Chromium, a real API process and a real
simulation): it starts the simulation of the selected motion, follows it, shows the report's
figures and its plot, and the simulated walk (blue) beside the motion (orange) in the 3D
preview. The browser setup is test_web_page's (Debian's chromium through playwright)."""

from __future__ import annotations

import numpy as np
from svc_util import KEY_A
from test_web_page import (  # noqa: F401
    SCREENSHOT,
    _missing,
    _open,
    _orange,
    _pixels,
    _state,
    browser,
    tutor_id,
    viewer,
    wait_js,
)

from service.routes.web import THREE_DIR


def _blue(img: np.ndarray) -> int:
    """Pixels of the simulated character (COMPANION_COLOR 0x3b7dd8, shaded): blue well above red and green."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return int(((b > 110) & (b - r > 60) & (b - g > 25)).sum())


def test_page_simulates_a_motion_and_shows_it_beside_the_motion(api, browser, tutor_id):  # noqa: F811
    if not THREE_DIR.is_dir():
        _missing("three.js is not installed: run `npm ci` in service/web")
    context, page, _requests, errors = _open(browser, 1400, 1100)
    try:
        page.goto(f"{api.base_url}/ui/#key={KEY_A}")
        page.wait_for_selector("#key-status.ok")
        page.wait_for_selector(f'#motion-list button[data-id="{tutor_id}"]')
        page.click(f'#motion-list button[data-id="{tutor_id}"]')
        wait_js(page, "(s => s.previewReady && s.simulationStatus)(window.motionx.state)")
        # out of range: the API's 422 is shown, nothing starts
        page.fill("#simulation-cycles", "0")
        page.click("#simulation-start")
        wait_js(page, "document.getElementById('simulation-status').textContent.startsWith('not started')")
        assert "cycles" in page.text_content("#simulation-status")
        assert api.a.get(f"/motions/{tutor_id}/simulation").status_code == 404

        page.fill("#simulation-cycles", "1")
        page.click("#simulation-start")
        wait_js(page, "(s => s.simulationShown && (s.simulationLoaded || s.simulationError))(window.motionx.state)",
                timeout=180)
        state = _state(page)
        assert state["simulationStatus"] == "succeeded" and state["simulationError"] is None, state
        assert state["simulationReport"]["cycles_walked"] > 0.99
        table = page.text_content("#simulation-report")
        assert "cycles walked" in table and "joint tracking RMS" in table and "real-time factor" in table, table
        assert "cycles completed from the reference state" in table and "1 of 1" in table, table
        assert page.evaluate("document.getElementById('simulation-img').naturalWidth") > 500
        assert page.locator("#simulation-downloads button").count() == 5

        # both characters in the preview: orange (the motion) and blue (simulated), side by side
        viewer(page, "v.setPlaying(false)")
        img = _pixels(page.locator("#viewer-canvas").screenshot())
        # both framed (the camera framed again on the two when the simulated walk came): every corner of each
        # character's box in view, as the user sees them now and as they start together
        framed = page.evaluate("(v => [v.inView(v.model), v.inView(v.companion.model)])(window.motionx.viewer)")
        viewer(page, "v.pairAt(0)")
        framed0 = page.evaluate("(v => [v.inView(v.model), v.inView(v.companion.model)])(window.motionx.viewer)")
        viewer(page, "v.setPlaying(true)")
        assert framed == [1, 1] and framed0 == [1, 1], (framed, framed0)
        area = img.shape[0] * img.shape[1]
        assert _orange(img) > 0.005 * area, "no motion character"
        assert _blue(img) > 0.005 * area, "no simulated character"
        assert page.evaluate("window.motionx.viewer.world.getObjectByName('companion') !== undefined")

        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SCREENSHOT.with_name("simulation.png")), full_page=True)
        assert not errors, errors
        assert not _state(page)["errors"]
    finally:
        context.close()
