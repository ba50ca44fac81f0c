"""The naturalness checks' limits and where each comes from.

``NaturalnessLimits`` holds every limit of the checks (``solver.naturalness``), ``SOURCES`` the
published source (or this project's reasoning) behind each, ``STAIRS_SWING`` the published peak
swing flexions on stairs. The optimizer's own bounds (``solver.spacetime``) are set against these.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class NaturalnessLimits:
    """Limits of the naturalness checks (BW = body weight). Sources: ``SOURCES``.

    Each limit lies outside what people do by a margin an optimum has no reason to reach: the
    optimizer costs each feature toward the capture's own figure (``solver.spacetime``), and its
    hard bounds, safety nets only, lie beyond these limits or at the model's."""

    clearance_m: float = 0.009  # mid-swing: heel, toe and sole at least this above the ground (people: 13 ± 4 mm)
    moving_speed: float = 1.0  # m/s: a swing point faster than this is in mid-swing (not lifting off or landing)
    #: the frames of a swing next to its lift-off and its touchdown are not mid-swing: there the foot
    #: leaves or meets the ground (its height goes to zero by definition), whatever its speed; Winter's
    #: minimum toe clearance is the trough of mid-swing
    swing_edge_frames: int = 1
    pitch_load: float = 0.5  # BW: a foot carrying more than this ...
    pitch_deg: float = 40.0  # ... is pitched (heel up or toe up) at most this
    limit_band_deg: float = 3.0  # a coordinate within this of its model limit is "at" it
    limit_frames: int = 1  # frames a coordinate may spend at a limit in a cycle
    joint_speed_deg_s: float = 450.0  # a joint coordinate's change between two frames, per second
    crossover_m: float = 0.03  # a loaded foot at most this far on the far side of the pelvis
    crossover_load: float = 0.1  # BW: "loaded"
    shared_load: float = 0.1  # BW: both feet carry at least this at some frame of a change of support
    fore_aft: float = 0.35  # BW per foot on level ground
    #: BW: a fore-aft force changes sign when it crosses ±this (mid-stance, where the force crosses zero
    #: slowly, a walk at 15 frames/s wiggles by a few hundredths: the issue is braking again after
    #: propelling, 0.1-0.2 BW each way)
    fore_aft_band: float = 0.05
    fore_aft_changes: int = 1  # braking → propulsion: sign changes per stance, level ground
    fore_aft_load: float = 0.1  # BW: a foot carrying less neither brakes nor propels (heel strike, toe-off)
    lateral: float = 0.15  # BW per foot on level ground (warning)
    lean_tol_deg: float = 2.0  # slopes: trunk lean against gravity vs the tutor's
    level_deg: float = 1.0  # ground within this of level (gravity direction), and no stairs, is "level ground"
    pelvis_pitch_range_deg: float = 12.0  # warnings: ranges over the cycle (yaw: about the heading's trend)
    pelvis_roll_range_deg: float = 20.0
    pelvis_yaw_range_deg: float = 25.0
    foot_heading_deg: float = 35.0  # warning: a loaded foot's heading off the pelvis's
    friction_use: float = 0.9  # required friction at most this fraction of μ (loaded feet)
    friction_load: float = 0.2  # BW: "loaded" for the friction margin
    peak_vertical: float = 1.5  # BW per foot on level ground (warning)
    push: float = -0.05  # warning: a loaded foot's horizontal force along foot → centre of mass ≥ this × f_z × leg
    hump: float = 0.03  # BW: a loading peak / push-off peak stands this above the mid-stance valley
    #: the capture's plates show a mid-stance valley when its peaks stand this far above it (BW): the
    #: motion's valley (``hump``) is then a failure, not a warning
    plates_hump: float = 0.1
    fit_marker_rms_mm: float = 20.0  # the capture's fit: marker RMS at most this (a broken fit is no reference)
    #: stairs: a swinging sole corner clears every nosing it passes by this (m, along the spline)
    nosing_clearance_m: float = 0.02
    #: stairs: a stance sole's corner stands at most this far over its tread's nosing ...
    tread_overhang_m: float = 0.02
    #: ... and at most this far into the riser of the tread above (a foot inside the step)
    tread_riser_m: float = 0.005
    #: stairs: spline samples per frame interval the nosing clearance is measured on
    stairs_swing_samples: int = 20


#: stairs: the published peak swing flexion (deg) of the knee and the hip, going up and down
#: (``SOURCES["stairs_swing"]``): the stairs_swing warnings compare a walk's peaks with the lower ends
STAIRS_SWING = {"up": {"knee": (90.0, 100.0), "hip": (55.0, 65.0)},
                "down": {"knee": (85.0, 100.0), "hip": (25.0, 40.0)}}


#: where each limit comes from. "This project's" marks a limit the literature does not give as a
#: number; docs/naturalness.md lists what each source reports and what the shared trials' own
#: captures and force plates show.
SOURCES = {
    "swing_clearance": "Winter 1992, Phys Ther 72:45 (minimum toe clearance in swing 1.29 cm, variability ~4 mm); "
                       "Begg et al. 2007, Gait Posture 25:191 (minimum foot clearance of young and elderly walkers); "
                       "9 mm is 13 mm less one standard deviation",
    "foot_pitch_under_load": "Perry & Burnfield, Gait Analysis (the heel rises in terminal stance, after mid-stance "
                             "has carried the weight on a flat foot; at heel strike the foot is ~20° toe-up and "
                             "lowers within 0.1 s as the load comes on); 40° either way at 0.5 BW is this "
                             "project's limit",
    "joint_limits": "the model's own joint limits (walking does not hold a joint at the end of its range)",
    "joint_speed": "Winter, Biomechanics and Motor Control of Human Movement (the fastest joint in walking, the knee "
                   "at toe-off and the ankle at push-off, turns at ~300-400°/s); a joint flapping between frames "
                   "is faster",
    "crossover": "Donelan, Kram & Kuo 2001, Proc R Soc B 268:1985 (preferred step width 0.13 leg lengths); "
                 "Taylor, Dabnichki & Strike 2005, Hum Mov Sci 24:558 (step turns keep a wide base of support)",
    "shared_load": "Perry & Burnfield; Kirtley, Clinical Gait Analysis (double support ~10-12 % of the cycle at "
                   "each change of support, both feet loaded)",
    "fore_aft_force": "Winter, Biomechanics and Motor Control of Human Movement (fore-aft peaks ~±0.2 BW at "
                      "natural speed); the shared trials' force plates: -0.22 to +0.28 BW",
    "fore_aft_pattern": "Winter; Kirtley (level walking: each stance brakes, then propels, the force crossing zero "
                        "once near mid-stance)",
    "fit_quality": "AddBiomechanics (Werling et al. 2023: marker RMS under 2 cm); OpenSim's best practice (marker "
                   "errors 1-2 cm): a capture fitted worse is no reference for a walk",
    "lateral_force": "Winter; Kirtley (mediolateral force ≲ 0.1 BW); the shared trials' force plates: ≤ 0.12 BW",
    "vertical_force_shape": "Kirtley (a loading peak ~20 % above body weight, a mid-stance valley below it); Keller "
                            "et al. 1996, Clin Biomech 11:253 (~1.2 BW peaks in walking)",
    "trunk_lean": "Prentice et al. 2004, Gait Posture 20:255 (the trunk pitches forward onto an uphill ramp); "
                  "Leroux, Fung & Barbeau 2002, Gait Posture 15:64 (postural adaptation to inclines)",
    "pelvis_ranges": "Perry & Burnfield; Kirtley (pelvic tilt, obliquity and rotation of a few degrees to ~10° in "
                     "level walking); the limit is also the capture's own range + 5°",
    "foot_heading": "Taylor, Dabnichki & Strike 2005; Glaister et al. 2007, Gait Posture 25:289 (turns by "
                    "stance-foot pivot and foot placement); 35° is this project's warning threshold",
    "friction_margin": "a slope needs at least tan(slope) of friction on average, and a walk that needs all of μ "
                       "slips at the slightest disturbance; the 10 % margin is this project's",
    "nosing_clearance": "Hamel, Okita, Higginson & Cavanagh 2005, Gait Posture 21:135 (foot clearance over stair "
                        "edges in descent); McFadyen & Winter 1988, J Biomech 21:733 (in ascent the swing leg "
                        "lifts the foot over the next step's edge); a toe or heel catching a nosing is the usual "
                        "stair trip; 2 cm is this project's margin",
    "stance_on_tread": "building codes' going (0.25-0.30 m: a foot fits on a tread); Riener, Rabuffetti & Frigo "
                       "2002, Gait Posture 15:32 (the forefoot lands first on the tread, up and down); a sole "
                       "corner 2 cm over the nosing or into the riser above is this project's limit",
    "stairs_swing": "McFadyen & Winter 1988, J Biomech 21:733 and Riener, Rabuffetti & Frigo 2002, Gait Posture "
                    "15:32 (step-over-step stairs of ~0.17 m rise, ~0.28 m going): peak swing knee flexion "
                    "~90-100° going up, ~85-100° going down; peak hip flexion ~55-65° going up, ~25-40° going down "
                    "(the ranges over the inclinations and subjects, read from their figures)",
    "push": "a walking leg pushes the body: its ground reaction points from the foot toward the centre of mass "
            "(the shared trials' force plates: ≥ -0.01 f_z × leg at every loaded frame)",
}

