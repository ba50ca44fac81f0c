"""Compiled derivative functions (solver.spacetime.compiled): the same NLP, faster.

The compiled Hessian and Jacobian blocks must be the virtual machine's functions in machine
code: the same IPOPT iterations and the same optimum, a cache that later processes reuse, and a
compiler failure that costs speed, never a result.
"""

import numpy as np
import pytest

from service.config import Settings, enable_native_code
from solver.pipeline import correct, make_tutor, problem_for
from solver.spacetime import FrameFunctions, compiled, frame_functions


@pytest.fixture(scope="module")
def pig_tutor(shared_data):
    from solver.io import load_trial

    compiled.enable(None)
    res = make_tutor(load_trial([shared_data / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d"]),
                     character="halfboy", fps=15)
    assert res.status == "succeeded", res.message
    return res


@pytest.fixture
def compile_dir(tmp_path):
    yield tmp_path
    compiled.enable(None)


def _correct(res):
    m = res.motion
    return correct(m.character, res.simplified.q, m.contacts, m.fps, init_wrenches=None,
                   heading_change=float(m.q[3, -2] - m.q[3, 0]))


def test_compiled_derivatives_solve_the_same_problem(pig_tutor, compile_dir):
    ch = pig_tutor.motion.character
    ff = frame_functions(ch)
    vm_problem = problem_for(ch, pig_tutor.motion.T, pig_tutor.motion.fps, pig_tutor.motion.contacts)
    before = _correct(pig_tutor)
    assert before.success and not ff.compiled

    assert compiled.enable(compile_dir)
    compiled.start(ff, wait=True)  # compiles (seconds), checks every function against the VM
    assert ff.compiled
    assert len(list(compile_dir.glob("derivatives-*.so"))) == 1
    assert vm_problem.stale  # built on the VM functions: problem_for rebuilds it
    fast = problem_for(ch, pig_tutor.motion.T, pig_tutor.motion.fps, pig_tutor.motion.contacts)
    assert fast is not vm_problem and not fast.stale
    after = _correct(pig_tutor)
    assert after.success
    assert after.iterations == before.iterations  # the same derivatives, so the same iterates
    np.testing.assert_allclose(after.q, before.q, atol=1e-8)
    np.testing.assert_allclose(after.objective, before.objective, rtol=1e-9)

    # a later process finds the library in the cache: loaded at once, no compile
    again = FrameFunctions(ch)
    assert compiled.start(again) is None and again.compiled


def test_a_failed_compile_keeps_the_virtual_machine(pig_tutor, compile_dir, caplog):
    ch = pig_tutor.motion.character
    assert compiled.enable(compile_dir, compiler="false")  # a "compiler" that always fails
    ff = FrameFunctions(ch)
    compiled.start(ff, wait=True)
    assert not ff.compiled
    assert "compiled NLP derivatives unavailable" in caplog.text
    assert list(compile_dir.glob("derivatives-*.failed"))  # remembered: no other process retries it
    caplog.clear()
    compiled.start(FrameFunctions(ch), wait=True)
    assert "an earlier compile failed" in caplog.text


def test_no_compiler_means_off(compile_dir, caplog):
    assert not compiled.enable(compile_dir, compiler="no-such-compiler-motionx")
    assert not compiled.enabled()
    assert "no C compiler" in caplog.text


def test_settings_turn_it_on_and_off(tmp_path):
    enable_native_code(Settings(data_dir=tmp_path, compiled_derivatives=True, compiled_dir=tmp_path / "cache"))
    try:
        assert compiled.enabled()
        assert Settings(data_dir=tmp_path).compiled_dir.parts[-2:] == ("motionx", "compiled")  # a cache
        enable_native_code(Settings(data_dir=tmp_path, compiled_derivatives=False))
        assert not compiled.enabled()
    finally:
        compiled.enable(None)


def test_the_cache_keeps_the_most_recent_libraries(tmp_path):
    import os

    for i, size in enumerate((300, 300, 300)):
        lib = tmp_path / f"derivatives-{i}.so"
        lib.write_bytes(b"\0" * size)
        os.utime(lib, (1000 + i, 1000 + i))  # 0 oldest, 2 newest
    gone = compiled.prune(tmp_path, keep=tmp_path / "derivatives-0.so", max_bytes=700)
    assert gone == [tmp_path / "derivatives-1.so"]  # the new library stays, then the most recent
    assert sorted(p.name for p in tmp_path.glob("*.so")) == ["derivatives-0.so", "derivatives-2.so"]
    assert compiled.prune(tmp_path, max_bytes=300) == [tmp_path / "derivatives-0.so"]
