"""The format registries (solver.formats) and the runners' (service.runners): the front ends
enumerate them, and every bad-input error of the readers shares one base."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import typing

import solver.io
from solver.errors import InputError
from solver.formats import EXPORTERS, READERS, export_media_types, reader_suffixes


def test_every_exporter_in_the_registry_is_callable_with_its_media_type():
    from solver.export import FORMATS, export_options, media_type

    assert list(FORMATS) == list(EXPORTERS)
    for name, e in EXPORTERS.items():
        func = getattr(importlib.import_module(e.module), e.function)
        assert callable(func) and media_type(name) == e.media_type
        for (option, value), mt in e.media_by_option.items():
            assert option in export_options(name) and media_type(name, **{option: value}) == mt
    assert set(export_media_types()) == {"application/json", "model/gltf-binary", "model/gltf+json", "text/plain",
                                        "application/zip"}


def test_front_ends_enumerate_the_registries():
    from service import uploads
    from service.cli import TRIAL_SUFFIXES
    from service.commands.export import CHOICES
    from service.routes.motions import FORMATS, ExportFormat

    assert set(uploads.TRIAL_SUFFIXES) == set(reader_suffixes()) == {
        ".osim", ".mot", ".sto", ".trc", ".xml", ".c3d", ".bvh", ".txt", ".json", ".glb", ".gltf"}
    assert set(TRIAL_SUFFIXES) <= set(reader_suffixes())
    assert tuple(EXPORTERS) == CHOICES
    assert FORMATS == (*EXPORTERS, "motion") == typing.get_args(ExportFormat)
    assert {r.name for r in READERS} == set(solver.io.READERS)


def test_runners_registry_matches_the_settings():
    from service.config import RUNNER_NAMES, Settings
    from service.runners import RUNNERS

    assert tuple(RUNNERS) == RUNNER_NAMES == typing.get_args(Settings.model_fields["runner"].annotation)


def test_every_reader_error_is_an_input_error():
    errors = []
    for m in pkgutil.walk_packages(solver.io.__path__, "solver.io."):
        if m.name.endswith(".worker"):  # the OpenSim child process's entry point
            continue
        mod = importlib.import_module(m.name)
        errors += [c for _, c in inspect.getmembers(mod, inspect.isclass)
                   if issubclass(c, Exception) and c.__module__ == m.name]
    from solver.gait import GaitError
    from solver.grf_compare import GRFFileError

    errors += [GaitError, GRFFileError]
    assert len(errors) >= 7
    assert all(issubclass(c, InputError) for c in errors), [c for c in errors if not issubclass(c, InputError)]
