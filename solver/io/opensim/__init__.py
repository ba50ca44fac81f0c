"""OpenSim importer: ``.osim`` model + ``.mot``/``.sto`` coordinates or ``.trc`` markers
(+ GRF ``.mot`` / ExternalLoads ``.xml``).

Public API::

    read_mot(path) -> Storage                                  # any OpenSim .mot/.sto table
    load_opensim(model, motion, *, mass=None, belt_speed=None, grf=None, grf_xml=None,
                 lower_only=None, in_degrees=None, floor_height=None, height=None,
                 ik_weights=None, ik_reweight=None) -> Capture  # motion: .mot/.sto or .trc
    opensim_track(model, motion, ...) -> SkeletonTrack         # the same, before fitting
    read_opensim_grf(mot, xml=None, *, times, frame=GroundFrame(), contacts=None,
                     threshold=20.0) -> MeasuredGRF
    plates_implied_mass(mot, xml=None, *, stride_s=None) -> ImpliedMass | None
    estimate_belt_speed(track) -> float                        # treadmill belt (m/s), from the stance feet

The package, one module per job: ``storage`` (.mot/.sto tables), ``worker`` (OpenSim in a
child process: model evaluation, inverse kinematics), ``ik`` (.trc -> coordinates),
``model`` (bodies -> our segments, landmarks, masses, inertias), ``external_loads`` (GRF
files, several forces per foot summed), ``treadmill`` (belt speed, Galilean shift).

**Columns of a .mot** that are not coordinates of the model are ignored with a warning when
constant (welded or locked joints, as OpenSim's tools ignore them) and refused, naming them,
when they vary (:func:`solver.io.opensim.model.check_motion`).

**The OpenSim model is evaluated by OpenSim itself** (PyPI ``opensim``): body frames in
ground for every frame (``initSystem``, coordinate values, ``realizePosition``,
``getTransformInGround``). The ``opensim`` wheel ships its own ``libcasadi.so.3.7`` with the
same soname as CasADi's but other symbols, so the two cannot live in one process: OpenSim
runs in a short-lived child process (``solver.io.opensim.worker``) that exchanges plain
numpy arrays with the caller. Models in the old 3.x format whose upgrade fails
``initSystem()`` (e.g. ``Rajagopal2016_subject05_v30516.osim``: joint sockets ``../pelvis``)
are repaired in memory: socket paths ``../(../)*body`` become ``/bodyset/body`` and the
force set, markers and probes (irrelevant to kinematics and inertia) are dropped.

**Axes.** OpenSim ground: X forward, Y up, Z right. Ours: X forward, Y left, Z up, so
``p_ours = C p_osim`` with ``C = [[1,0,0],[0,0,-1],[0,1,0]]``; body orientations become
``C R C^T`` (OpenSim bodies are ground-aligned in the default pose, as our segments at
q = 0). ``GroundFrame.R = C^T``; ``offset`` = the floor height in OpenSim ground (0 unless
``floor_height`` is given or the GRF file's centre of pressure tells it, e.g. -0.0075 m on
the treadmill trial); ``velocity`` = the belt velocity when ``belt_speed`` is set.

**Body -> segment map** (by name; a body no rule knows is lumped into its parent's segment):

==========================  =============================================================
OpenSim bodies              our segment (orientation taken from the first body listed)
==========================  =============================================================
pelvis                      pelvis
femur_s                     thigh_s
tibia_s (+ patella_s)       shank_s
calcn_s + talus_s           foot_s  (talus: ankle landmark; calcn: heel, orientation)
toes_s                      toes_s
torso                       abdomen + thorax + head (mass split by Winter's ratios
                            0.139 : 0.196 : 0.081, each part at the torso's centre of mass
                            with its share of the torso's inertia: together, rigid with the
                            torso, they are the torso body; the clavicles, which such a model
                            does not have, are placeholders of negligible mass) — or, without
                            arms in the model (gait2354: the torso body is head, arms and
                            trunk), the abdomen alone, with the body's own mass, centre of
                            mass and inertia (see below)
humerus_s                   upper_arm_s
radius_s + ulna_s           forearm_s
hand_s                      hand_s
==========================  =============================================================

**Landmarks** (all from the evaluated model): pelvis = mid-point of the hip joint centres;
hip/knee/ankle/mtp = centres of the joints whose child is femur/tibia/talus/toes (child
frame origin in ground); lumbar = centre of the joint whose child is the torso; shoulder,
elbow, wrist = centres of the joints whose child is humerus, ulna, hand. The foot's sole is
found from the data: *heel* = the calcn origin moved down along the calcn's vertical to the
sole, *toe* = the toes origin moved forward along the toes' x by twice the toes' centre of
mass abscissa (the far end of the toes, the COM being mid-length) and down to the sole; the
sole lies ``sole`` below the calcn origin, ``sole`` = the calcn origin's height above the
floor at mid-stance (2nd percentile over the trial). Without a torso body the upper body
is absent (capture-lower). A torso body without arms (gait2354) gives a ``capture-full``
skeleton whose abdomen *is* the torso, driven by the lumbar coordinates: the canonical
upper-body landmarks (neck, head top, sternum, shoulders, elbows, wrists, hands: the neutral
pose of ``capture_full`` for the subject's height) ride rigidly on the torso from the lumbar
joint, and the thorax, head, clavicle and arm segments are placeholders of negligible mass
(``PLACEHOLDER_MASS_FRACTION`` of the subject each, taken from the torso: MuJoCo refuses
massless moving bodies). The trunk thus keeps its real motion and mass distribution;
``lower_only=True`` lumps it into the pelvis (``merge_segments``). With arms, the torso carries neck (on the torso's
vertical through the shoulder centres, 6 % of body height above them), head top (13 %
above the neck) and sternum (between the shoulders, 4 % of height forward and 8 % down):
they are rigidly attached to the torso, so they only set the neck/head lengths of the
capture skeleton (OpenSim's torso includes the head). Hand tip = wrist + twice the hand's
COM offset. Body height, when the source does not give it, is estimated by the fit.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path

from solver.capture import Capture
from solver.gait import detect_contacts, gait_events
from solver.io.fit import fit_track
from solver.io.mass import ImpliedMass, implied_mass, mass_warning, stride_from_events
from solver.io.opensim.base import C_OSIM, OpenSimError
from solver.io.opensim.external_loads import grf_arrays, read_opensim_grf
from solver.io.opensim.model import PLACEHOLDER_MASS_FRACTION, opensim_evaluation, opensim_track
from solver.io.opensim.rig import OpenSimRig, opensim_rig
from solver.io.opensim.storage import Storage, read_mot
from solver.io.opensim.treadmill import estimate_belt_speed
from solver.io.readers import TrialError, by_suffix

log = logging.getLogger(__name__)

__all__ = [
    "C_OSIM",
    "PLACEHOLDER_MASS_FRACTION",
    "OpenSimError",
    "Storage",
    "estimate_belt_speed",
    "load_opensim",
    "opensim_track",
    "plates_implied_mass",
    "read_mot",
    "read_opensim_grf",
    "trial_files",
]


def plates_implied_mass(mot: str | Path, xml: str | Path | None = None, *,
                        stride_s: float | None = None) -> ImpliedMass | None:
    """The body mass a GRF file implies (:func:`solver.io.mass.implied_mass` on the whole
    record at the plates' rate, every force of a foot summed); None when it cannot tell."""
    sto, F, _, _ = grf_arrays(mot, xml)
    return implied_mass(sto.time, F[:, :, 1], stride_s=stride_s)


def is_grf_mot(path: Path) -> bool:
    """Whether an OpenSim table holds forces (a GRF file) rather than coordinates."""
    sto = read_mot(path)
    return any(lab.endswith(("force_vx", "_vx")) and "force" in lab for lab in sto.labels)


def trial_files(paths: list[Path]) -> dict[str, Path | None]:
    """An OpenSim trial's files by role (the reader registry's ``trial_files``): the model, one
    coordinates ``.mot``/``.sto`` or markers ``.trc``, at most one GRF ``.mot`` (told by its
    force columns) and an ExternalLoads ``.xml`` with it."""
    by_ext = by_suffix(paths)
    if len(by_ext[".osim"]) != 1:
        raise TrialError(f"one OpenSim model expected, got {by_ext['.osim']}")
    mots = by_ext.get(".mot", []) + by_ext.get(".sto", [])
    grfs = [m for m in mots if is_grf_mot(m)]
    kin = [m for m in mots if m not in grfs] + by_ext.get(".trc", [])
    if len(kin) != 1:
        raise TrialError(f"an OpenSim trial needs exactly one coordinates .mot/.sto or one markers .trc next to "
                         f"the model; got {[str(k) for k in kin]} (GRF files: {[str(g) for g in grfs]})")
    if len(grfs) > 1:
        raise TrialError(f"at most one GRF .mot, got {[str(g) for g in grfs]}")
    xmls = by_ext.get(".xml", [])
    if len(xmls) > 1 or (xmls and not grfs):
        raise TrialError(f"an ExternalLoads .xml goes with one GRF .mot; got xml {xmls}, GRF {grfs}")
    return {"model": by_ext[".osim"][0], "motion": kin[0], "grf": grfs[0] if grfs else None,
            "grf_xml": xmls[0] if xmls else None}


def load_opensim(
    model: str | Path,
    motion: str | Path,
    *,
    mass: float | None = None,
    belt_speed: float | str | None = None,
    grf: str | Path | None = None,
    grf_xml: str | Path | None = None,
    lower_only: bool | None = None,
    in_degrees: bool | None = None,
    floor_height: float | None = None,
    height: float | None = None,
    ik_weights: Mapping[str, float] | None = None,
    ik_reweight: int | None = None,
) -> Capture:
    """Import an OpenSim trial as a :class:`Capture` (see the package doc for every convention).

    ``motion``: the coordinates (``.mot``/``.sto``, e.g. an IK result) or the marker
    trajectories (``.trc``: OpenSim's inverse kinematics against the model's markers first,
    ``ik_weights`` / ``ik_reweight`` see :mod:`solver.io.opensim.ik`). ``mass`` (kg) rescales
    the model's segment masses when it differs from the model's total (the model's own total
    is used by default). ``belt_speed``: treadmill belt speed (m/s) or ``"auto"``; the root is
    shifted by ``v·t`` and ``GroundFrame.velocity`` records it. ``grf``/``grf_xml``: measured
    ground reactions (``read_opensim_grf``), attached as ``capture.measured`` with ``valid``
    computed from the kinematic contact schedule; the mass they imply is in
    ``capture.source["implied_mass"]`` and a disagreement of more than 5 % with the mass used
    is logged and kept in ``source["mass_warning"]``. ``capture.rig``: what writing results
    back on the model needs (:mod:`solver.io.opensim.rig`, :mod:`solver.export.opensim`).
    """

    track, res = opensim_evaluation(model, motion, mass=mass, belt_speed=belt_speed, grf=grf, grf_xml=grf_xml,
                                    in_degrees=in_degrees, floor_height=floor_height, height=height,
                                    ik_weights=ik_weights, ik_reweight=ik_reweight)
    cap = fit_track(track, lower_only=lower_only)
    cap = cap.evolve(rig=opensim_rig(model, res, cap))
    if grf is not None:
        contacts = detect_contacts(cap.character, cap.q, cap.fps)
        measured = read_opensim_grf(grf, grf_xml, times=cap.times, frame=cap.frame, contacts=contacts)
        src = dict(cap.source)
        src["grf"] = str(Path(grf).resolve())
        src["grf_valid_frames"] = int(measured.valid.sum())
        implied = plates_implied_mass(grf, grf_xml, stride_s=stride_from_events(gait_events(contacts, cap.times)))
        if implied is not None:
            src["implied_mass"] = implied.as_dict()
            src["mass_implied_kg"] = round(implied.kg, 2)
            src["mass_implied_from"] = f"plates: {implied.method}"
            warn = mass_warning(cap.character.total_mass, implied)
            if warn:
                log.info("%s: %s", Path(grf).name, warn)  # source["mass_warning"]: the front ends show it
                src["mass_warning"] = warn
        complete = cap.times[measured.valid]
        assert isinstance(cap.rig, OpenSimRig)  # opensim_rig
        rig = cap.rig.evolve(plates={
            "grf": str(Path(grf).resolve()),
            "external_loads": None if grf_xml is None else str(Path(grf_xml).resolve()),
            "complete_s": [float(complete[0]), float(complete[-1])] if complete.size else None})
        cap = cap.evolve(measured=measured, source=src, rig=rig)
    return cap
