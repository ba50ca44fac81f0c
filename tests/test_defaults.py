"""The character and frame rate a user gets by default (issue: true to the subject): the full body at
30 frames/s in the solver, the command line and the service; HalfBoy at 15 when it is asked for."""

import inspect

from service.config import Settings
from solver.pipeline import DEFAULT_CHARACTER, default_fps, make_tutor


def test_the_solver_defaults_to_the_full_body_at_30_fps():
    sig = inspect.signature(make_tutor)
    assert sig.parameters["character"].default == DEFAULT_CHARACTER == "fullbody"
    assert sig.parameters["fps"].default is None
    assert default_fps("fullbody") == 30.0 and default_fps("halfboy") == 15.0


def test_the_command_line_defaults_to_the_solvers(monkeypatch):
    from service.cli import build_parser

    args = build_parser().parse_args(["tutor", "x.c3d", "--out", "t.json"])
    assert args.character == DEFAULT_CHARACTER and args.fps is None


def test_the_service_defaults_to_the_solvers_and_fills_what_a_request_omits(monkeypatch):
    monkeypatch.delenv("MOTIONX_DEFAULT_CHARACTER", raising=False)
    monkeypatch.delenv("MOTIONX_DEFAULT_TUTOR_FPS", raising=False)
    s = Settings()
    assert s.default_character == DEFAULT_CHARACTER
    assert s.tutor_of(None) == ("fullbody", 30.0)
    assert s.tutor_of({"character": None, "fps": None}) == ("fullbody", 30.0)
    assert s.tutor_of({"character": "halfboy"}) == ("halfboy", 15.0)
    assert s.tutor_of({"character": "halfboy", "fps": 30}) == ("halfboy", 30.0)
    monkeypatch.setenv("MOTIONX_DEFAULT_CHARACTER", "halfboy")
    assert Settings().tutor_of({}) == ("halfboy", 15.0)
