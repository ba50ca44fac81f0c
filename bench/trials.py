"""The walking trials the benchmarks run on (the repository's data/, or $MOTIONX_DATA)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

from service import examples


def best_time(fn: Callable[[], object], repeat: int) -> float:
    """The best of ``repeat`` wall-clock timings of ``fn()`` (s)."""
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def data_dir() -> Path:
    d = examples.data_dir()
    if not d.is_dir():
        raise FileNotFoundError(f"walking data not found at {d} (the repository's data/, or $MOTIONX_DATA)")
    return d


def trials() -> dict[str, list[Path]]:
    d = data_dir()
    return {
        "deepmimic_walk": [d / "deepmimic_humanoid3d_walk" / "humanoid3d_walk.txt",
                           d / "deepmimic_humanoid3d_walk" / "humanoid3d_character.txt"],
        "opensim_overground": [d / "opensim_loadedwalking_subject05" / "Rajagopal2016_subject05_v30516.osim",
                               d / "opensim_loadedwalking_subject05"
                               / "loadedwalking_subject05_noload_free_trial03_ik_solution.mot"],
        "c3d_pig": [d / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d"],
    }


def shared_trials() -> dict[str, tuple[list[Path], dict]]:
    """Every shared walking trial the naturalness targets name (issue: natural walks): the two
    OpenSim walks, the two C3D walks, the DeepMimic walk and the CMU straight walk, with the
    options ``load_trial`` needs."""
    d = data_dir()
    tm, lw = d / "opensim_gait2354_subject01_treadmill", d / "opensim_loadedwalking_subject05"
    return {
        "opensim_overground": ([lw / "Rajagopal2016_subject05_v30516.osim",
                                lw / "loadedwalking_subject05_noload_free_trial03_ik_solution.mot",
                                lw / "loadedwalking_subject05_noload_free_trial03_grf.mot"], {}),
        "opensim_treadmill": ([tm / "subject01.osim", tm / "subject01_walk1_ik.mot", tm / "subject01_walk1_grf.mot",
                               tm / "subject01_walk1_grf.xml"], {"belt_speed": "auto"}),
        "c3d_pig": ([d / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d"], {}),
        "c3d_qualisys": ([d / "qualisys_ior_walk" / "Qualisys.c3d"], {"mass": 66.0}),
        "deepmimic_walk": (trials()["deepmimic_walk"], {}),
        "cmu_straight": ([d / "cmu16_bvh" / "16_15_walk.bvh"], {"mass": 60.0}),
    }


def other_labs_dir() -> Path | None:
    """Where the other labs' walks are kept (not in this repository: fetched material is not committed
    here, the tool library's rule): ``$MOTIONX_OTHER_LABS_DATA``; None when it is not set or does not
    hold them."""
    d = os.environ.get("MOTIONX_OTHER_LABS_DATA")
    if d and (Path(d) / "c3d_motion_analysis_helen_hayes").is_dir() and (Path(d) / "c3d_opensim_walking5").is_dir():
        return Path(d)
    return None


def other_labs() -> dict[str, tuple[list[Path], dict]]:
    """Public walks from other labs and marker sets than ``shared_trials``,
    each with its origin and licence (``other_labs_dir``): a Motion Analysis Helen Hayes set with medial
    markers, a Vicon Nexus cluster set (opensim-core's walking5), with the masses their plates imply;
    none when they are not there."""
    d = other_labs_dir()
    if d is None:
        return {}
    return {
        "c3d_motion_analysis": ([d / "c3d_motion_analysis_helen_hayes" / "Gait.c3d"], {"mass": 64.4}),
        "c3d_opensim_walking5": ([d / "c3d_opensim_walking5" / "walking5.c3d"], {"mass": 56.1}),
    }
