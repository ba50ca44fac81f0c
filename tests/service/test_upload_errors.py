"""A trial upload that cannot be imported gets a 422 in the client's words: its own file
names (never the server's temporary folder) and, for a file that states no subject mass, the
form field to send (not the Python argument, not the CLI flag)."""

from __future__ import annotations

import pytest

from service.uploads import UploadError, motion_from_trial


@pytest.fixture(scope="module")
def bvh_bytes(shared_data, tmp_path_factory) -> bytes:
    from test_io_bvh import write_bvh

    d = shared_data / "deepmimic_humanoid3d_walk"
    p = tmp_path_factory.mktemp("bvh") / "walk.bvh"
    write_bvh(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt", p)
    return p.read_bytes()


def no_server_path(message: str) -> None:
    assert "motionx-upload-" not in message and "/tmp" not in message and "<upload>" not in message, message


def test_import_errors_name_the_clients_file_only():
    for files in ([("fake.bvh", b"not a bvh at all")], [("walk.c3d", b"\x00\x01" * 64)],
                  [("m.osim", b"<OpenSimDocument/>"), ("c.mot", b"nonsense")]):
        with pytest.raises(UploadError) as e:
            motion_from_trial(files, mass=60.0, belt_speed=None)
        no_server_path(str(e.value))
        assert files[0][0] in str(e.value) or "OpenSim" in str(e.value), str(e.value)


def test_a_trial_without_mass_names_the_form_field(bvh_bytes):
    with pytest.raises(UploadError) as e:
        motion_from_trial([("walk.bvh", bvh_bytes)], mass=None, belt_speed=None)
    msg = str(e.value)
    assert "subject mass unknown" in msg and "send the form field 'mass' (kg)" in msg
    assert "mass=..." not in msg and "--mass" not in msg
    no_server_path(msg)
    motion = motion_from_trial([("walk.bvh", bvh_bytes)], mass=45.0, belt_speed=None)
    assert motion.character.total_mass == pytest.approx(45.0)


def test_over_http(api, bvh_bytes):
    r = api.a.post("/motions", files={"files": ("fake.bvh", b"not a bvh at all")})
    assert r.status_code == 422
    no_server_path(r.text)
    assert "fake.bvh" in r.text
    r = api.a.post("/motions", files={"files": ("walk.bvh", bvh_bytes)})
    assert r.status_code == 422 and "send the form field 'mass' (kg)" in r.text, r.text


def test_every_importer_option_is_a_form_field():
    from service.routes.motions import MULTIPART_FIELDS
    from solver.formats import reader_options

    assert set(reader_options()) <= set(MULTIPART_FIELDS)


@pytest.mark.parametrize("fields, words", [
    ({"lower_only": "maybe"}, "lower_only must be true or false"),
    ({"units": "furlong"}, "units must be one of auto, cm, m, mm, in, cmu"),
    ({"up": "x"}, "up must be y or z"),
    ({"markers": "/etc/passwd"}, "is not ROLE=label"),
    ({"markers": "LASI=L_IAS,1X=y"}, "'1X=y' is not ROLE=label"),
])
def test_bad_importer_options_are_refused_clearly(fields, words):
    from service.uploads import trial_options

    with pytest.raises(UploadError, match=words):
        trial_options(fields)


def test_importer_options_reach_the_reader(bvh_bytes):
    """The form's text becomes the reader's options, and they reach the reader: lower_only fits
    fewer coordinates; an option of another format is refused by name."""
    from service.uploads import trial_options

    opts = trial_options({"units": "m", "up": "y", "lower_only": "true"})
    assert opts == {"units": "m", "up": "y", "lower_only": True}
    whole = motion_from_trial([("walk.bvh", bvh_bytes)], mass=45.0, belt_speed=None)
    lower = motion_from_trial([("walk.bvh", bvh_bytes)], mass=45.0, belt_speed=None, lower_only=True)
    assert lower.character.n < whole.character.n  # the lower body only
    with pytest.raises(UploadError, match="markers"):  # an option of another reader is refused, by name
        motion_from_trial([("walk.bvh", bvh_bytes)], mass=45.0, belt_speed=None, markers={"LASI": "L_IAS"})
