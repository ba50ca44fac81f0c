"""What the API answers says, and what it does not: no internal exception text (OpenSim's C++
messages, a Python TypeError) and no more than a short excerpt of the client's own input; λ and
times rounded to what they mean; a motion file read the same whether sent as the JSON body or as
a multipart file; a large trial refused by the frames it declares before it is parsed."""

from __future__ import annotations

import json
import struct
import time

import pytest
from svc_util import halfboy_motion

from service import limits
from service.config import Settings
from service.uploads import UploadError, motion_from_trial
from service.views import progress_out

INTERNALS = (".cpp:", "SimTK", "std::", "Error detected by", "Traceback", "TypeError", "::")


def no_internals(text: str) -> None:
    for needle in INTERNALS:
        assert needle not in text, (needle, text)


# --- no internals, no long echo ------------------------------------------------------------------


def test_a_long_unknown_path_is_not_echoed(api):
    r = api.a.get("/" + "a" * 5000)
    assert r.status_code == 404, r.text[:300]
    body = r.json()
    assert len(body["instance"]) <= 200 and body["instance"].endswith("…"), body["instance"][:300]
    assert len(r.content) < 1000


def test_a_malformed_opensim_model_is_named_without_opensim_internals(shared_data):
    """OpenSim's own text was a SimTK exception naming Xml.cpp and the method that threw."""
    d = shared_data / "opensim_gait2354_subject01_treadmill"
    mot = (d / "subject01_walk1_ik.mot").read_bytes()
    osim = (d / "subject01.osim").read_bytes()
    for bad in (osim[: len(osim) // 2], b"hello"):
        with pytest.raises(UploadError) as e:
            motion_from_trial([("model.osim", bad), ("walk_ik.mot", mot)], mass=None, belt_speed=None)
        msg = str(e.value)
        no_internals(msg)
        assert "model.osim" in msg and "OpenSim" in msg, msg


def test_a_job_that_trips_on_an_unexpected_error_says_so_without_its_text(tmp_path):
    """A job whose stored spec the solver cannot use (``target`` is not a mapping) fails with a
    generic message; Python's own text (``TypeError: argument after ** must be a mapping``) stays
    in the server's log."""
    from service import store
    from service.db import get_database, upgrade
    from service.jobs import execute_job

    settings = Settings(data_dir=tmp_path, runner="local")
    upgrade(settings.sqlalchemy_url)
    db = get_database(settings.sqlalchemy_url)
    with db.write() as s:
        m = store.add_motion(s, owner="o", motion=halfboy_motion(12, capture=False), kind="motion")
        job = store.create_job(s, owner="o", motion_id=m.id, spec={"target": True}, runner="local",
                               max_attempts=1)
        job_id = job.id
    assert execute_job(job_id, settings) == "failed"
    with db.read() as s:
        message = store.get_job(s, job_id=job_id, owner=None).message
    assert message == "internal error while running the job (logged on the server)", message


# --- values rounded to what they mean --------------------------------------------------------------


def test_lambda_and_times_are_reported_rounded():
    from service.models import ProgressRow

    lam = 0.05 + 0.1
    assert lam != 0.15  # the solver's arithmetic
    row = ProgressRow(job_id="j", attempt=1, seq=2, phase="extrapolate", wall_time=1.23456789, lam=lam,
                      lam_reached=0.05 + 0.1 + 0.2, environment={"slope_deg": -11.25 * lam}, iterations=7,
                      accepted=True, status="Solve_Succeeded", at=0.0)
    out = progress_out(row)
    assert out["lam"] == 0.15 and out["lam_reached"] == 0.35 and out["wall_time"] == 1.235
    assert out["environment"]["slope_deg"] == -1.6875
    assert json.dumps(out["lam"]) == "0.15"


# --- a motion file as a multipart file --------------------------------------------------------------


def test_a_motion_file_is_read_the_same_as_body_or_multipart_file(api):
    text = halfboy_motion(20, capture=False).to_json()
    body = api.a.post("/motions", content=text, headers={"content-type": "application/json"})
    assert body.status_code == 201, body.text
    form = api.a.post("/motions", files={"files": ("tutor.json", text.encode())})
    assert form.status_code == 201, form.text
    a, b = body.json(), form.json()
    for k in ("kind", "character", "coordinates", "frames", "fps", "has_wrenches"):
        assert a[k] == b[k], k
    assert api.a.get(a["links"]["motion_file"]).content == api.a.get(b["links"]["motion_file"]).content
    r = api.a.post("/motions", files={"files": ("tutor.json", text.encode())}, data={"mass": "70"})
    assert r.status_code == 422 and "motion file" in r.json()["detail"], r.text


# --- large trials refused by what they declare, before their import ------------------------------


def refused_quickly(files, needle: str) -> str:
    t0 = time.perf_counter()
    with pytest.raises(UploadError) as e:
        motion_from_trial(files, mass=70.0, belt_speed=None)
    took = time.perf_counter() - t0
    assert needle in str(e.value), str(e.value)
    assert took < 3.0, took
    return str(e.value)


def test_a_coordinates_file_with_too_many_rows_is_refused_before_opensim(shared_data):
    """100,000 rows at 1 kHz (100 s, within the duration limit): before, OpenSim evaluated them
    all in the compute process for its whole time limit (120 s), blocking every other upload
    and export."""
    d = shared_data / "opensim_gait2354_subject01_treadmill"
    head, body = (d / "subject01_walk1_ik.mot").read_text().split("endheader", 1)
    lines = body.strip().splitlines()
    row = lines[1].split()[1:]
    n = limits.MAX_CAPTURE_FRAMES * 3
    rows = "\n".join("\t".join([f"{i * 0.001:.3f}", *row]) for i in range(n))
    mot = f"{head}endheader\n{lines[0]}\n{rows}\n".encode()
    msg = refused_quickly([("subject01.osim", (d / "subject01.osim").read_bytes()), ("walk_ik.mot", mot)],
                          f"at most {limits.MAX_CAPTURE_FRAMES} frames, this one has {n}")
    assert "walk_ik.mot" in msg


def test_a_marker_file_with_too_many_frames_is_refused_before_its_inverse_kinematics(shared_data):
    d = shared_data / "opensim_gait2354_subject01_treadmill"
    lines = (d / "marker_trajectories.trc").read_bytes().splitlines()
    data = [ln for ln in lines[5:] if ln.strip()]
    n = limits.MAX_CAPTURE_FRAMES + 100
    trc = b"\n".join(lines[:5] + [data[i % len(data)] for i in range(n)]) + b"\n"
    refused_quickly([("subject01.osim", (d / "subject01.osim").read_bytes()), ("markers.trc", trc)],
                    f"at most {limits.MAX_CAPTURE_FRAMES} frames")


def test_a_c3d_is_refused_by_the_frames_its_header_declares(shared_data):
    raw = bytearray((shared_data / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d").read_bytes())
    first, last = struct.unpack_from("<HH", raw, 6)
    assert (first, last) == (148, 462)  # the file's own header (Intel byte order; frames count from 1)
    struct.pack_into("<H", raw, 8, 0xFFFF)  # the 16-bit last frame full: at least 65,535 frames
    refused_quickly([("walk.c3d", bytes(raw))], f"at most {limits.MAX_CAPTURE_FRAMES} frames")
    struct.pack_into("<H", raw, 8, last)
    struct.pack_into("<f", raw, 20, 1.0)  # 315 frames at 1 Hz: 314 s
    refused_quickly([("walk.c3d", bytes(raw))], f"at most {limits.MAX_CAPTURE_S:g} s")


def test_a_capture_whose_provenance_cannot_rebuild_it_is_refused_at_upload(api):
    """``"source": true`` was stored, and the job then failed on Python's TypeError."""
    for source in (True, [1, 2], "text"):
        d = halfboy_motion(20).to_dict()
        d["provenance"]["source"] = source
        r = api.a.post("/motions", content=json.dumps(d), headers={"content-type": "application/json"})
        assert r.status_code == 422, (source, r.text)
        no_internals(r.json()["detail"])
        assert "provenance of a capture" in r.json()["detail"]
    ok = halfboy_motion(20).to_dict()
    ok["provenance"]["source"] = {"format": "test"}
    r = api.a.post("/motions", content=json.dumps(ok), headers={"content-type": "application/json"})
    assert r.status_code == 201
