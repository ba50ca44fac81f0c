"""A folder given where the trial's files are expected is named as a folder (it was "file not
found"), with the trial files it holds, by the importer and by `motionx tutor`."""

from __future__ import annotations

import pytest

from service.cli import main
from solver.io import TrialError, load_trial


def test_a_folder_is_named_as_a_folder(shared_data):
    d = shared_data / "opensim_gait2354_subject01_treadmill"
    with pytest.raises(TrialError) as e:
        load_trial(d)
    msg = str(e.value)
    assert "is a folder" in msg and "not found" not in msg and "subject01.osim" in msg, msg


def test_motionx_tutor_on_a_folder(shared_data, tmp_path, capsys):
    d = shared_data / "opensim_gait2354_subject01_treadmill"
    assert main(["tutor", str(d), "--out", str(tmp_path / "t.json")]) == 2
    err = capsys.readouterr().err
    assert "is a folder; give the trial's files" in err and "file not found" not in err, err
    assert not (tmp_path / "t.json").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["tutor", str(empty), "--out", str(tmp_path / "t.json")]) == 2
    assert "is a folder" in capsys.readouterr().err
