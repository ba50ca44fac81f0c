"""Gait cycles: one cycle with its overlap frames out of a trial (or of a looping clip), and
unrolling a looping clip.
"""

from __future__ import annotations

import logging

import numpy as np

from solver.capture import Capture, MeasuredGRF
from solver.gait.base import GaitError, resample, unwrap_hinges
from solver.gait.contacts import detect_contacts

log = logging.getLogger(__name__)


def unroll_loop(capture: Capture, repeats: int = 2) -> Capture:
    """A looping clip (its last frame is the phase of its first) repeated ``repeats`` times.

    As DeepMimic's ``"Loop": "wrap"``: each repetition is translated horizontally by the
    clip's root displacement (last - first frame, vertical component ignored); orientations
    are not accumulated. The first frame of every repetition after the first is dropped (it
    is the previous repetition's last frame). Hinge angles are unwrapped first.
    """
    if repeats < 1:
        raise GaitError("unroll_loop: repeats must be >= 1")
    if capture.T < 3:
        raise GaitError("unroll_loop: a loop needs at least 3 frames")
    ch = capture.character
    q = unwrap_hinges(ch, capture.q)
    t = capture.times
    names = ch.coordinate_names
    period = t[-1] - t[0]
    disp = np.zeros(ch.n)
    for nm in ("root_tx", "root_ty"):
        if nm in names:
            i = names.index(nm)
            disp[i] = q[i, -1] - q[i, 0]
    qs, ts = [q], [t]
    contacts = capture.contacts
    cs = [contacts] if contacts is not None else None
    for r in range(1, repeats):
        qs.append(q[:, 1:] + r * disp[:, None])
        ts.append(t[1:] + r * period)
        if cs is not None and contacts is not None:
            cs.append(contacts[:, 1:])
    src = dict(capture.source)
    src["unrolled_loops"] = repeats
    return capture.evolve(q=np.hstack(qs), times=np.concatenate(ts),
                          contacts=None if cs is None else np.hstack(cs), measured=None, source=src)


def extract_cycle(
    capture: Capture,
    fps: float | None = None,
    *,
    start: str = "right_heel_strike",
    contacts: np.ndarray | None = None,
    cycle: int = 0,
) -> tuple[Capture, np.ndarray]:
    """One gait cycle with the two overlap frames the cyclic constraint needs (docs/method.md (M5.5)).

    The capture is first resampled to ``fps`` (if given). The contact schedule is ``contacts``
    if given, else the capture's own (e.g. from force plates), else :func:`detect_contacts`.
    With strikes of the ``start`` foot
    at frames s and s + N (the next strike), the cycle is frames s .. s + N + 1 (T = N + 2):
    frames T-1 and T repeat frames 1 and 2 one period later (q_1 = q_{T-1}, q_2 = q_T for the
    non-root coordinates). ``cycle`` picks which complete cycle (0 = the first). A looping
    clip (``capture.source["loop"] == "wrap"``, its last frame at the phase of its first) is
    one cycle already: the cycle is the clip plus the loop's second frame (T = clip + 1),
    starting at the clip's boundary when the ``start`` strike is within 2 frames of it
    (cyclically), otherwise at the strike (the loop's closure error then falls inside the
    cycle). Returns the cycle's Capture (its ``contacts`` set) and its (P, T) contacts.
    """
    if start == "auto":
        errors: list[tuple[str, str | None]] = []
        for st in ("right_heel_strike", "left_heel_strike", "best_loop"):
            try:
                return extract_cycle(capture, fps, start=st, contacts=contacts, cycle=cycle)
            except GaitError as e:
                if e.reason not in [r for r, _ in errors]:  # the same reason once, not once per start
                    errors.append((e.reason, e.parameter))
        param = next((p for _, p in errors if p), None)
        raise GaitError("extract_cycle: no gait cycle found: " + " | ".join(r.removeprefix("extract_cycle: ")
                                                                           for r, _ in errors), parameter=param)
    if start not in ("right_heel_strike", "left_heel_strike", "best_loop"):
        raise GaitError("extract_cycle: start must be 'right_heel_strike', 'left_heel_strike', 'best_loop' "
                              f"or 'auto', not {start!r}")
    cap = resample(capture, fps) if fps is not None else capture
    cyc, cc = _cycle_of(cap, start, contacts, cycle)
    if fps is None or cap.source.get("loop") == "wrap":
        return cyc, cc
    return _exact_period(capture, cyc, float(fps), contacts)


def _cycle_of(cap: Capture, start: str, contacts: np.ndarray | None, cycle: int) -> tuple[Capture, np.ndarray]:
    """The cycle of :func:`extract_cycle` on the capture as sampled (its period a whole number of
    frames)."""
    if contacts is None:
        contacts = cap.contacts  # e.g. from force plates (resampled with the capture); else detected below
    if cap.source.get("loop") == "wrap":
        return _extract_loop_cycle(cap, start, contacts)
    if contacts is None:
        contacts = detect_contacts(cap.character, cap.q, cap.fps)
    contacts = np.asarray(contacts, dtype=bool)
    if contacts.shape != (len(cap.character.contacts), cap.T):
        raise GaitError(f"extract_cycle: contacts must be ({len(cap.character.contacts)}, T={cap.T}), "
                              f"got {contacts.shape}")
    if contacts.shape[0] != 4:
        raise GaitError("extract_cycle: expected 4 contact points (heel_r, toe_r, heel_l, toe_l)")
    feet = np.stack([contacts[0] | contacts[1], contacts[2] | contacts[3]])
    for k, side in enumerate(("right", "left")):
        if not feet[k].any():
            raise GaitError(f"extract_cycle: the {side} foot is never on the ground in this clip (a foot is down where "
                            "it is low and still); a clip that walks in place (no root motion) is a walk on a moving "
                            "ground: give its walking speed (m/s) or 'auto'", parameter="belt_speed")
    if start == "best_loop":
        return _best_loop_cycle(cap, contacts, feet)
    k = 0 if start.startswith("right") else 1
    d = np.diff(feet[k].astype(int))
    strikes = np.where(d == 1)[0] + 1
    side = "right" if k == 0 else "left"
    if strikes.size == 0:
        raise GaitError(f"extract_cycle: no {side} heel strike found in {cap.T} frames "
                              f"({cap.times[-1] - cap.times[0]:.2f} s)")
    usable = [s for s in strikes[:-1] if s + 1 + (strikes[strikes > s][0] - s) < cap.T] if strikes.size > 1 else []
    if len(usable) <= cycle:
        raise GaitError(
            f"extract_cycle: clip too short for a gait cycle: {strikes.size} {side} heel strike(s) at "
            f"{[round(float(cap.times[s]), 3) for s in strikes]} s; a cycle needs two strikes and one frame after "
            f"the second (cycle={cycle} asked)"
        )
    s0 = usable[cycle]
    s1 = strikes[strikes > s0][0]
    sl = slice(s0, s1 + 2)
    cc = contacts[:, sl]
    fc = feet[:, sl][:, :-2]
    if not np.any(fc[0] & fc[1]):
        raise GaitError("extract_cycle: no double support in the cycle (is this a walk? running has none)")
    if not fc[1 - k].any():
        raise GaitError(f"extract_cycle: the {'left' if k == 0 else 'right'} foot never touches the ground "
                              "during the cycle")
    cycle_info = {"start": start, "index": cycle, "frames": [int(s0), int(s1 + 1)],
                  "t_start": float(cap.times[s0]), "period_s": float(cap.times[s1] - cap.times[s0]),
                  "overlap_frames": 2}
    return _cycle_capture(cap, sl, cc, cycle_info), cc


def _cycle_capture(cap: Capture, sl: slice, contacts: np.ndarray, cycle_info: dict) -> Capture:
    """The frames ``sl`` of a capture (plates included) with the cycle recorded in its source."""
    m = cap.measured
    meas = None
    if m is not None:
        meas = MeasuredGRF(force=m.force[..., sl], cop=m.cop[..., sl], free_moment=m.free_moment[..., sl],
                           valid=m.valid[sl], source=m.source)
    src = dict(cap.source)
    src["cycle"] = cycle_info
    return Capture(character=cap.character, q=cap.q[:, sl], times=cap.times[sl], frame=cap.frame, source=src,
                   contacts=contacts, measured=meas)


#: the window (s) after the cycle's start and after its end one period later whose match
#: decides the period (``_exact_period``), and the resolution of the search (frames)
PERIOD_WINDOW_S = 0.25
PERIOD_STEP_FRAMES = 0.05
#: the captured motion (s) kept before and after a cycle (``Capture.lead_in``, ``lead_out``) and the
#: window over which ``close_loop`` blends it in
LEAD_S = 0.2


def _exact_period(capture: Capture, cyc: Capture, fps: float,
                  contacts: np.ndarray | None) -> tuple[Capture, np.ndarray]:
    """The cycle resampled so that its N frames span the capture's own period exactly.

    A cycle cut at ``fps`` spans a whole number N of frames, so its period is off the subject's
    by up to half a frame (33 ms at 15 frames/s, 3 % of a stride): its last frames are then a
    phase ahead of or behind its first, and a periodic motion fitted to it jumps between them
    (the overground walk's tutor: the knee 16° in one frame). The period P is found on the
    capture at its own rate — the P within a frame of N / fps whose motion over
    ``PERIOD_WINDOW_S`` after the cycle's start best matches the same window one period later
    (normalized joint coordinates, root height, pitch and roll, as the best loop matches) — and
    the capture is resampled at P / N from the cycle's start: the cycle keeps N frames at
    N / P frames per second (the requested rate within half a frame per cycle), the subject's
    own cadence and timing."""
    from scipy.interpolate import CubicSpline  # lazy, as in resample

    info = dict(cyc.source.get("cycle") or {})
    T = cyc.T
    N = T - 2
    t0 = float(cyc.times[0])
    t = capture.times
    if capture.T < 4 or N < 4:
        return cyc, cyc.contacts if cyc.contacts is not None else np.zeros((4, T), dtype=bool)
    periodic = np.zeros(capture.character.n, dtype=bool)
    periodic[6:] = True
    periodic[[2, 4, 5]] = True
    q = unwrap_hinges(capture.character, capture.q)[periodic]
    spline = CubicSpline(t, q / np.maximum(np.std(q, axis=1, keepdims=True), 1e-3), axis=1)
    half = 0.5 * min(PERIOD_WINDOW_S, 0.25 * N / fps)
    p0 = N / fps
    best_p, best_err = p0, None
    reach = 2.0 if info.get("start") == "best_loop" else 1.0  # a loop's N came from two frames' match alone
    for df in np.arange(-reach, reach + 1e-9, PERIOD_STEP_FRAMES):
        p = p0 + df / fps
        a, b = max(t0 - half, t[0]), min(t0 + half, t[-1] - p)  # the motion around the start, one period later
        if b - a < 2.0 / fps:
            continue
        tau = np.linspace(a, b, 16)
        err = float(np.mean((spline(tau) - spline(tau + p)) ** 2))
        if best_err is None or err < best_err - 1e-12:
            best_p, best_err = p, err
    if best_err is None:
        return cyc, cyc.contacts if cyc.contacts is not None else np.zeros((4, T), dtype=bool)
    N = max(4, int(round(best_p * fps)))
    T = N + 2
    span = best_p * (N + 1) / N  # the cycle and its overlap frame
    if t0 + span > t[-1] + 1e-9:
        if info.get("start") != "best_loop" or t[-1] - span < t[0] - 1e-9:
            return cyc, cyc.contacts if cyc.contacts is not None else np.zeros((4, T), dtype=bool)
        t0 = float(t[-1] - span)  # a loop may start anywhere: earlier, so that a whole period fits
        info["t_start"] = t0
    fps_eff = N / best_p
    dt = best_p / N
    k = int(min(round(LEAD_S * fps_eff), np.floor((t0 - t[0]) / dt + 1e-9)))  # frames before the start
    grid = resample(capture, fps_eff, start=t0 - k * dt)
    if k + T > grid.T:
        return cyc, cyc.contacts if cyc.contacts is not None else np.zeros((4, T), dtype=bool)
    if contacts is None and grid.contacts is None:
        contacts = detect_contacts(grid.character, grid.q, grid.fps)
    elif contacts is not None:  # a schedule given on the requested grid: nearest frame in time
        given = resample(capture, fps)
        idx = np.clip(np.rint((grid.times - given.times[0]) * fps).astype(int), 0, given.T - 1)
        contacts = np.asarray(contacts, dtype=bool)[:, idx]
    else:
        contacts = grid.contacts
    sl = slice(k, k + T)
    cc = np.asarray(contacts, dtype=bool)[:, sl]
    info.update({"period_s": float(best_p), "fps": float(fps_eff), "fps_requested": float(fps),
                 "frames_per_cycle": int(N)})
    q_grid = unwrap_hinges(grid.character, grid.q)
    lead_out = q_grid[:, k + T: k + T + int(round(LEAD_S * fps_eff))]
    out = _cycle_capture(grid, sl, cc, info).evolve(lead_in=q_grid[:, :k] if k else None,
                                                      lead_out=lead_out if lead_out.shape[1] else None)
    return out, cc


#: plausible walking cycle durations (s) searched by the best-loop cycle
LOOP_PERIOD_S = (0.7, 2.0)


def _best_loop_cycle(cap: Capture, contacts: np.ndarray, feet: np.ndarray) -> tuple[Capture, np.ndarray]:
    """A cycle for trials shorter than two strikes of one foot: the period N and start s whose
    frames (s, s+1) best match (s+N, s+N+1) — joint coordinates, root height, pitch and roll,
    and the contact schedule (which must repeat exactly) — as in motion-graph loop detection.
    The cycle must contain double support and both feet's stances."""
    T, fps = cap.T, cap.fps
    lo = max(4, int(round(LOOP_PERIOD_S[0] * fps)))
    hi = min(T - 2, int(round(LOOP_PERIOD_S[1] * fps)))
    if hi < lo:
        raise GaitError(f"extract_cycle: {T} frames ({cap.times[-1] - cap.times[0]:.2f} s) are too few for "
                              f"a gait cycle of at least {LOOP_PERIOD_S[0]} s plus two overlap frames")
    periodic = np.zeros(cap.character.n, dtype=bool)
    periodic[6:] = True
    periodic[[2, 4, 5]] = True
    qp = cap.q[periodic]
    scale = np.maximum(np.std(qp, axis=1, keepdims=True), 1e-3)
    qn = qp / scale
    best = None
    for N in range(lo, hi + 1):
        for s0 in range(0, T - N - 1):
            if not np.array_equal(contacts[:, s0 : s0 + 2], contacts[:, s0 + N : s0 + N + 2]):
                continue
            fc = feet[:, s0 : s0 + N]
            if not (np.any(fc[0] & fc[1]) and fc[0].any() and fc[1].any() and (~fc[0]).any() and (~fc[1]).any()):
                continue
            err = float(np.sum((qn[:, s0 : s0 + 2] - qn[:, s0 + N : s0 + N + 2]) ** 2))
            if best is None or err < best[0]:
                best = (err, s0, N)
    if best is None:
        raise GaitError("extract_cycle: no loop of a walking period closes in this clip (the contact schedule "
                              "never repeats with double support and both stances inside)")
    err, s0, N = best
    sl = slice(s0, s0 + N + 2)
    cc = contacts[:, sl]
    cycle_info = {"start": "best_loop", "index": 0, "frames": [int(s0), int(s0 + N + 1)],
                  "t_start": float(cap.times[s0]), "period_s": float(N / fps), "overlap_frames": 2,
                  "loop_mismatch_rms_std": float(np.sqrt(err / (2 * qn.shape[0])))}
    return _cycle_capture(cap, sl, cc, cycle_info), cc


def _extract_loop_cycle(cap: Capture, start: str, contacts: np.ndarray | None) -> tuple[Capture, np.ndarray]:
    Tc = cap.T - 1  # the last frame is the first one's phase
    if Tc < 4:
        raise GaitError(f"extract_cycle: a looping clip of {cap.T} frames is too short for a gait cycle")
    if contacts is None:
        contacts = detect_contacts(cap.character, cap.q, cap.fps)
    contacts = np.asarray(contacts, dtype=bool)
    if contacts.shape != (4, cap.T):
        raise GaitError(f"extract_cycle: contacts must be (4, T={cap.T}), got {contacts.shape}")
    cyc = contacts[:, :Tc]
    feet = np.stack([cyc[0] | cyc[1], cyc[2] | cyc[3]])
    for k, side in enumerate(("right", "left")):
        if not feet[k].any():
            raise GaitError(f"extract_cycle: the {side} foot is never on the ground in this clip")
        if feet[k].all():
            raise GaitError(f"extract_cycle: the {side} foot never leaves the ground in this clip")
    if not np.any(feet[0] & feet[1]):
        raise GaitError("extract_cycle: no double support in the clip (is this a walk? running has none)")
    k = 0 if start.startswith("right") else 1
    strikes = [i for i in range(Tc) if feet[k][i] and not feet[k][i - 1]]
    side = "right" if k == 0 else "left"
    if not strikes:
        raise GaitError(f"extract_cycle: no {side} heel strike found in the looping clip")
    dist = [min(i, Tc - i) for i in strikes]
    s0 = 0 if min(dist) <= 2 else strikes[0]
    u = unroll_loop(cap, 3)
    sl = slice(s0, s0 + Tc + 2)
    idx = np.arange(s0, s0 + Tc + 2) % Tc
    cc = cyc[:, idx]
    src = dict(cap.source)
    src["cycle"] = {"start": start, "index": 0, "frames": [int(s0), int(s0 + Tc)],
                    "t_start": float(u.times[s0]), "period_s": float(u.times[s0 + Tc] - u.times[s0]),
                    "overlap_frames": 2, "loop": True,
                    "strike_frame": int(strikes[int(np.argmin(dist))])}
    if s0 != 0:
        log.warning("extract_cycle: the looping clip's boundary falls inside the cycle (closure error of the loop "
                    "included)")
    out = Capture(character=cap.character, q=u.q[:, sl], times=u.times[sl], frame=cap.frame, source=src,
                  contacts=cc, measured=None)
    return out, cc


def close_loop(q: np.ndarray, *, keep_yaw: bool = True, lead_in: np.ndarray | None = None,
               lead_out: np.ndarray | None = None) -> np.ndarray:
    """A captured cycle (n, T: frames T−2, T−1 one period after frames 0, 1) made periodic.

    A captured cycle does not close: its second stride is not its first (the overground walk's
    knee is 2° and 4°/frame off one period later, in swing where it turns fastest). A periodic
    motion fitted to it puts the whole mismatch between the overlap frames and the next (the
    tutor's knee turned 16° in one frame). As a game engine blends a loop, the cycle's last
    frames are crossfaded (smoothstep over ``LEAD_S``) into the motion that led into its first
    (``lead_in``, the captured frames before it): frames T−2, T−1 become frames 0, 1 and the
    seam is the subject's own motion. Without a lead-in its first frames are crossfaded from the
    motion that followed its last (``lead_out``); without either, the closure error is spread
    as a ramp over the cycle. The root's horizontal translation is left as it is, and its yaw
    when ``keep_yaw`` (a curve turns by its heading change; a straight walk's yaw drift goes)."""
    q = np.array(q, dtype=float, copy=True)
    T = q.shape[1]
    N = T - 2
    if N < 2:
        return q
    rows = [i for i in range(q.shape[0]) if i not in (0, 1) and not (i == 3 and keep_yaw)]
    W_in = 0 if lead_in is None else min(int(lead_in.shape[1]), N - 2)
    W_out = 0 if lead_out is None else min(int(lead_out.shape[1]) + 2, N - 2)
    if W_in >= 2:  # the last frames blend into the lead-in, shifted one period on
        assert lead_in is not None
        for t in range(N - W_in, T):
            j = t - N  # the frame relative to frame 0 one period on
            src = lead_in[rows, lead_in.shape[1] + j] if j < 0 else q[rows, j]
            s = float(np.clip((t - (N - W_in)) / W_in, 0.0, 1.0))
            w = s * s * (3 - 2 * s)
            if j >= 0:
                q[rows, t] = src
                continue
            q[rows, t] = (1 - w) * q[rows, t] + w * src
        return q
    if W_out >= 3:  # the first frames blend from the lead-out, shifted one period back
        assert lead_out is not None
        ext = np.concatenate([q[rows, N:], lead_out[rows]], axis=1)  # frames N, N+1, N+2, ...
        for t in range(W_out):
            s = float(np.clip(t / (W_out - 1), 0.0, 1.0))
            w = 1 - s * s * (3 - 2 * s)
            q[rows, t] = w * ext[:, t] + (1 - w) * q[rows, t]
        q[rows, N:] = q[rows, :2]
        return q
    ramp = np.arange(T) / N
    for i in rows:
        q[i] -= ramp * (q[i, N] - q[i, 0])
    return q


#: the band (Hz) over which ``periodic_lowpass`` rolls off: gait kinematics are low-passed at ~6 Hz
#: (Winter, Biomechanics and Motor Control of Human Movement); the walk's own harmonics lie below
PERIODIC_CUTOFF_HZ = (6.0, 10.0)


def periodic_lowpass(q: np.ndarray, fps: float, band: tuple[float, float] = PERIODIC_CUTOFF_HZ) -> np.ndarray:
    """A closed cycle (n, T: frames T−2, T−1 equal to frames 0, 1 one period on) low-passed as the
    periodic signal it is: the harmonics of its period above ``band[1]`` Hz removed, those between
    ``band[0]`` and ``band[1]`` faded (raised cosine), no phase shift and no edge. The root's
    horizontal translation and yaw keep their trend over the cycle (the walker's travel and turn)
    and lose only their noise. A capture's glitch (the DeepMimic walk's trunk turns 14° between two
    frames at 30 frames/s) is a harmonic far above a walk's."""
    q = np.array(q, dtype=float, copy=True)
    T = q.shape[1]
    N = T - 2
    if N < 4 or not (fps > 0):
        return q
    ramp = np.arange(T) / N
    trend = np.zeros_like(q)
    for i in (0, 1, 3):  # travel and turn: linear over the cycle
        if i < q.shape[0]:
            trend[i] = ramp * (q[i, N] - q[i, 0])
    x = (q - trend)[:, :N]
    X = np.fft.rfft(x, axis=1)
    f = np.fft.rfftfreq(N, d=1.0 / fps)
    lo, hi = band
    gain = np.where(f <= lo, 1.0, np.where(f >= hi, 0.0, 0.5 * (1 + np.cos(np.pi * (f - lo) / max(hi - lo, 1e-9)))))
    y = np.fft.irfft(X * gain, n=N, axis=1)
    out = np.concatenate([y, y[:, :2]], axis=1) + trend
    return out
