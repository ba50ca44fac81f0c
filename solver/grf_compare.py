"""Estimated vs measured ground reactions: the estimate CSV, comparison metrics, plot.

:class:`GroundReactions` holds per-foot ground reactions on a time grid in one frame:
force (N), centre of pressure (a point on the ground), free moment about the vertical at
the CoP (N·m). :func:`to_input_frame` maps an estimate from our world frame to a trial's
own ground frame and units with its :class:`~solver.capture.GroundFrame` (forces rotated,
CoPs mapped as points at their times — a treadmill's belt motion included); the CSV of
``motionx grf`` is that, one row per frame and foot.

:func:`compare` computes the thesis's Table 4.1 metrics (docs/method.md (M4)): per component the RMS
and max of the error and the relative RMS (docs/method.md (M4.8))

    RMS / (½ [(max x − min x) + (max e − min e)])

with the amplitudes taken over the double-support frames (the thesis's choice; all
compared frames when there is no double support). Components: force along our world axes
(x forward, y left, z up), free moment, and CoP distance (compared only where both the
measured and the estimated vertical force exceed ``cop_min_load`` of the peak measured
vertical force: a CoP is undefined under no load and meaningless under a small one).
Samples of both feet are pooled, over the frames where the measured reaction is complete;
:func:`per_foot` gives the same metrics foot by foot. :func:`feet_on_plates` is the
geometric check that a loaded foot stands on a plate (a C3D's plate outlines and foot
landmarks), so a frame where a foot carries load off the plates is never compared.

The estimate's free moment is not reported (:func:`from_estimate` leaves it NaN, the CSV's
``tz`` is ``nan``): on every shared trial with plates its error exceeds that of predicting
zero (docs/grf.md); ``free_moment=True`` keeps it for analysis.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from solver.capture import GroundFrame
from solver.errors import InputError
from solver.io.c3d.events import feet_on_plates  # noqa: F401  (the check grf-compare applies)

FEET = ("right", "left")
CSV_COLUMNS = ("time", "side", "fx", "fy", "fz", "cop_x", "cop_y", "cop_z", "tz")
COMPONENTS = ("fx", "fy", "fz", "tz", "cop")
UNITS = {"fx": "N", "fy": "N", "fz": "N", "tz": "N·m", "cop": "cm"}
COP_MIN_LOAD = 0.05  # fraction of the peak measured vertical force


class GRFFileError(InputError):
    """A ground-reaction file is malformed; the message names the problem."""


def _frozen(a: Any, dtype: Any = float) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class GroundReactions:
    """Per-foot ground reactions (feet ordered right, left) on ``times`` (T,).

    ``force`` (2, 3, T) N; ``cop`` (2, 3, T) in the frame's length unit (NaN where the
    foot carries no load); ``free_moment`` (2, T) N·m about the vertical at the CoP;
    ``valid`` (T,) frames where the reaction is known (estimate defined / plates complete).
    """

    times: np.ndarray
    force: np.ndarray
    cop: np.ndarray
    free_moment: np.ndarray
    valid: np.ndarray = None  # type: ignore[assignment]  # None: frames with finite forces (__post_init__)

    def __post_init__(self) -> None:
        T = np.asarray(self.times).shape[0]
        object.__setattr__(self, "times", _frozen(self.times))
        for name, shape in (("force", (2, 3, T)), ("cop", (2, 3, T)), ("free_moment", (2, T))):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != shape:
                raise ValueError(f"GroundReactions.{name} must have shape {shape}, got {a.shape}")
            object.__setattr__(self, name, _frozen(a))
        valid = np.all(np.isfinite(self.force), axis=(0, 1)) if self.valid is None else self.valid
        object.__setattr__(self, "valid", _frozen(valid, bool))

    @property
    def T(self) -> int:
        return int(self.times.shape[0])

    def resample(self, times: np.ndarray) -> GroundReactions:
        """Linear interpolation onto ``times``; frames outside the span are invalid."""
        t = np.asarray(times, dtype=float)
        inside = (t >= self.times[0] - 1e-9) & (t <= self.times[-1] + 1e-9)

        def interp(a: np.ndarray) -> np.ndarray:
            flat = a.reshape(-1, self.T)
            return np.stack([np.interp(t, self.times, row, left=np.nan, right=np.nan) for row in flat]).reshape(
                a.shape[:-1] + (len(t),))

        # a sample is valid when both neighbours are valid
        v = np.interp(t, self.times, self.valid.astype(float), left=0.0, right=0.0) > 1.0 - 1e-9
        return GroundReactions(t, interp(self.force), interp(self.cop), interp(self.free_moment), v & inside)


# --- frames -------------------------------------------------------------------------------


def to_input_frame(gr: GroundReactions, frame: GroundFrame) -> GroundReactions:
    """Our world frame (SI) -> the input's ground frame: forces rotated (N), CoPs as points at
    their times (input length unit, treadmill belt motion included), free moment unchanged
    (a moment about the same physical vertical)."""
    force = np.moveaxis(frame.vector_to_input(np.moveaxis(gr.force, 1, -1)), -1, 1)
    cop = np.moveaxis(frame.point_to_input(np.moveaxis(gr.cop, 1, -1), gr.times), -1, 1)
    return GroundReactions(gr.times, force, cop, gr.free_moment, gr.valid)


def from_input_frame(gr: GroundReactions, frame: GroundFrame) -> GroundReactions:
    """Inverse of :func:`to_input_frame`."""
    force = np.moveaxis(frame.vector_from_input(np.moveaxis(gr.force, 1, -1)), -1, 1)
    cop = np.moveaxis(frame.point_from_input(np.moveaxis(gr.cop, 1, -1), gr.times), -1, 1)
    return GroundReactions(gr.times, force, cop, gr.free_moment, gr.valid)


# --- the estimate CSV ------------------------------------------------------------------------


def _fmt(x: float) -> str:
    return "nan" if not math.isfinite(x) else f"{x:.6g}"


def write_csv(path: str | Path, gr: GroundReactions) -> int:
    """One row per valid frame and foot (right then left): ``time, side, fx, fy, fz, cop_x,
    cop_y, cop_z, tz``. CoP is ``nan`` for an unloaded foot. Returns the number of rows."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    rows = 0
    for t in np.flatnonzero(gr.valid):
        for s, side in enumerate(FEET):
            vals = [*gr.force[s, :, t], *gr.cop[s, :, t], gr.free_moment[s, t]]
            w.writerow([f"{gr.times[t]:.6f}", side, *(_fmt(float(v)) for v in vals)])
            rows += 1
    Path(path).write_text(buf.getvalue())
    return rows


def read_csv(path: str | Path) -> GroundReactions:
    """Read a ``motionx grf`` CSV back (same frame and units as written)."""
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise GRFFileError(f"estimate file not found: {p}") from None
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        raise GRFFileError(f"{p}: empty file")
    missing = [c for c in CSV_COLUMNS if c not in header]
    if missing:
        raise GRFFileError(f"{p}: missing columns {missing} (expected {list(CSV_COLUMNS)})")
    col = {c: header.index(c) for c in CSV_COLUMNS}
    data: dict[float, dict[str, list[float]]] = {}
    for lineno, row in enumerate(reader, start=2):
        if not row:
            continue
        try:
            t = float(row[col["time"]])
            side = row[col["side"]].strip()
            vals = [float(row[col[c]]) for c in CSV_COLUMNS[2:]]
        except (ValueError, IndexError):
            raise GRFFileError(f"{p}:{lineno}: malformed row {row!r}") from None
        if side not in FEET:
            raise GRFFileError(f"{p}:{lineno}: side must be 'right' or 'left', got {side!r}")
        if not all(math.isfinite(v) for v in vals[:3]):
            raise GRFFileError(f"{p}:{lineno}: force must be finite")
        if side in data.setdefault(t, {}):
            raise GRFFileError(f"{p}:{lineno}: duplicate row for time {t} and side {side}")
        data[t][side] = vals
    if not data:
        raise GRFFileError(f"{p}: no rows")
    times = np.array(sorted(data))
    for t in times:
        if len(data[t]) != 2:
            raise GRFFileError(f"{p}: time {t} lacks a row for one foot (need right and left)")
    arr = np.array([[data[t][s] for t in times] for s in FEET])  # (2, T, 7)
    arr = np.moveaxis(arr, 1, 2)  # (2, 7, T)
    return GroundReactions(times, arr[:, 0:3], arr[:, 3:6], arr[:, 6])


# --- metrics ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Row:
    component: str
    unit: str
    rms: float
    max: float
    rel_rms: float
    samples: int


@dataclass(frozen=True)
class Comparison:
    frames: str  # "all" or "double support"
    rows: tuple[Row, ...]
    n_frames: int

    def row(self, component: str) -> Row:
        for r in self.rows:
            if r.component == component:
                return r
        raise KeyError(component)

    def as_dict(self) -> dict:
        return {"frames": self.frames, "n_frames": self.n_frames,
                "rows": {r.component: {"unit": r.unit, "rms": r.rms, "max": r.max, "rel_rms": r.rel_rms,
                                       "samples": r.samples} for r in self.rows}}


def _amplitude(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(x.max() - x.min()) if x.size else math.nan


def _stats(err: np.ndarray, meas_amp: np.ndarray, est_amp: np.ndarray) -> tuple[float, float, float, int]:
    e = err[np.isfinite(err)]
    if e.size == 0:
        return math.nan, math.nan, math.nan, 0
    rms = float(np.sqrt(np.mean(e**2)))
    amp = 0.5 * (_amplitude(meas_amp) + _amplitude(est_amp))
    return rms, float(np.max(np.abs(e))), (rms / amp if amp > 0 else math.nan), int(e.size)


def compare(
    estimate: GroundReactions,
    measured: GroundReactions,
    *,
    double_support: np.ndarray | None = None,
    length_unit_m: float = 1.0,
    vertical: int = 2,
    cop_min_load: float = COP_MIN_LOAD,
    feet: Sequence[int] = (0, 1),
    single_support: list | None = None,
    loaded_only: bool = False,
) -> tuple[Comparison, Comparison | None]:
    """Table 4.1 metrics over all compared frames, and over the double-support ones.

    Both series on the same times and in the same frame (force components along that
    frame's axes; ``vertical`` is the index of its vertical axis). Frames compared: valid in
    both. ``double_support`` (T,) marks double-support frames (for the relative-RMS
    amplitudes and the second table); by default, frames where both measured vertical forces
    exceed ``cop_min_load`` of the peak. ``feet``: whose samples are pooled (0 right, 1 left).
    ``single_support``: a list that receives the table over the other compared frames (same
    amplitudes), or None there is none. ``loaded_only``: a foot's samples count only where it carries
    load (measured or estimated vertical force above ``cop_min_load`` of the peak; the pooled thesis
    metric counts the swing foot's zeros too).
    """
    if estimate.T != measured.T or not np.allclose(estimate.times, measured.times, atol=1e-6):
        raise ValueError("estimate and measurement must share their time grid (resample first)")
    both = estimate.valid & measured.valid
    if not both.any():
        raise ValueError("no frame where both the estimate and the measured ground reaction are known")
    fz_m = measured.force[:, vertical, :]
    fz_e = estimate.force[:, vertical, :]
    peak = float(np.nanmax(np.where(both, np.nansum(fz_m, axis=0), np.nan)))
    thr = cop_min_load * peak
    if double_support is None:
        double_support = np.all(fz_m > thr, axis=0)
    ds = np.asarray(double_support, dtype=bool) & both
    amp_frames = ds if ds.any() else both

    fs = list(feet)
    ef, mf = estimate.force[fs], measured.force[fs]
    et, mt = estimate.free_moment[fs], measured.free_moment[fs]
    if loaded_only:  # unloaded samples (a foot in the air by both accounts) leave the errors
        idle = ~((fz_m[fs] > thr) | (fz_e[fs] > thr))
        ef = np.where(idle[:, None], np.nan, ef)
        et = np.where(idle, np.nan, et)

    def table(frames: np.ndarray, label: str) -> Comparison:
        rows = []
        axes = [i for i in range(3) if i != vertical]
        names = {axes[0]: "fx", axes[1]: "fy", vertical: "fz"}
        for k in range(3):
            e, m = ef[:, k][:, frames], mf[:, k][:, frames]
            rms, mx, rel, n = _stats(e - m, mf[:, k][:, amp_frames], ef[:, k][:, amp_frames])
            rows.append(Row(names[k], "N", rms, mx, rel, n))
        rows.sort(key=lambda r: r.component)
        rows.append(Row("tz", "N·m", *_stats(et[:, frames] - mt[:, frames], mt[:, amp_frames], et[:, amp_frames])))
        loaded = (fz_m[fs][:, frames] > thr) & (fz_e[fs][:, frames] > thr)
        d = np.linalg.norm(estimate.cop[fs][:, :, frames] - measured.cop[fs][:, :, frames], axis=1)
        d = np.where(loaded, d * length_unit_m * 100.0, np.nan)
        rms, mx, _, n = _stats(d, np.array([]), np.array([]))
        rows.append(Row("cop", "cm", rms, mx, math.nan, n))
        return Comparison(label, tuple(rows), int(frames.sum()))

    if single_support is not None:
        ss = both & ~ds
        single_support.append(table(ss, "single support") if ss.any() else None)
    return table(both, "all"), (table(ds, "double support") if ds.any() else None)


def format_table(comp: Comparison) -> str:
    lines = [f"frames: {comp.frames} ({comp.n_frames})",
             f"{'component':<10} {'unit':<5} {'RMS':>9} {'max':>9} {'rel. RMS':>9} {'samples':>8}"]
    for r in comp.rows:
        if r.samples == 0:
            what = "not estimated (docs/grf.md)" if r.component == "tz" else "–"
            lines.append(f"{r.component:<10} {r.unit:<5} {what:>29} {0:>8}")
            continue
        rel = "–" if not math.isfinite(r.rel_rms) else f"{100 * r.rel_rms:.1f} %"
        lines.append(f"{r.component:<10} {r.unit:<5} {r.rms:>9.2f} {r.max:>9.2f} {rel:>9} {r.samples:>8}")
    return "\n".join(lines)


# --- plot ------------------------------------------------------------------------------------


def plot(
    path: str | Path,
    estimate: GroundReactions,
    measured: GroundReactions,
    *,
    axis_names: Sequence[str] = ("x", "y", "z"),
    length_unit: str = "m",
    vertical: int = 2,
    double_support: np.ndarray | None = None,
    title: str = "",
) -> None:
    """PNG of estimated (dashed) vs measured (solid) curves: forces, free moment, CoP."""
    import matplotlib  # lazy: matplotlib only for this figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib only for this figure

    t = estimate.times
    fig, axes = plt.subplots(6, 1, figsize=(9, 14), sharex=True)
    colors = {"right": "tab:red", "left": "tab:blue"}
    panels: list[tuple[str, Callable[..., Any]]] = [
        (f"f{axis_names[k]} (N)", lambda g, s, k=k: g.force[s, k]) for k in range(3)]
    panels.append(("free moment (N·m)", lambda g, s: g.free_moment[s]))
    panels += [(f"CoP {axis_names[k]} ({length_unit})", lambda g, s, k=k: g.cop[s, k])
               for k in range(3) if k != vertical]
    both = estimate.valid & measured.valid
    for ax, (label, get) in zip(axes, panels):
        for s, side in enumerate(FEET):
            ax.plot(t, np.where(measured.valid, get(measured, s), np.nan), color=colors[side], lw=1.5,
                    label=f"{side} measured")
            ax.plot(t, np.where(estimate.valid, get(estimate, s), np.nan), color=colors[side], lw=1.2, ls="--",
                    label=f"{side} estimated")
        if double_support is not None:
            ds = np.asarray(double_support, bool) & both
            ax.fill_between(t, 0, 1, where=ds, color="tab:green", alpha=0.12, transform=ax.get_xaxis_transform(),
                            lw=0)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=4, fontsize=8, loc="upper right")
    axes[-1].set_xlabel("time (s)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def from_estimate(estimate: Any, times: np.ndarray, *, free_moment: bool = False) -> GroundReactions:
    """A :class:`~solver.contact.ContactEstimate` as :class:`GroundReactions` (our frame, SI); the free
    moment NaN (not reported, see the module doc) unless ``free_moment``."""
    tz = estimate.free_moment if free_moment else np.full(estimate.free_moment.shape, np.nan)
    return GroundReactions(np.asarray(times, dtype=float), estimate.force, estimate.cop, tz, estimate.defined)


def from_measured(measured: Any, times: np.ndarray) -> GroundReactions:
    """A :class:`~solver.capture.MeasuredGRF` (our frame, on the capture's times) as :class:`GroundReactions`."""
    return GroundReactions(np.asarray(times, dtype=float), measured.force, measured.cop, measured.free_moment,
                           measured.valid)


def plates_complete(estimate: GroundReactions, measured: GroundReactions, on_plates: np.ndarray,
                    threshold: float = 20.0, vertical: int = 2) -> np.ndarray:
    """(T,) frames where every foot that carries load — by the plates or by the estimate (> ``threshold``
    N) — stands on a plate (``on_plates`` (2, T), :func:`feet_on_plates`): only there do the plates
    measure the whole ground reaction the estimate is compared with."""
    loaded = (np.nan_to_num(measured.force[:, vertical]) > threshold) | (np.nan_to_num(estimate.force[:, vertical])
                                                                          > threshold)
    return np.all(~loaded | np.asarray(on_plates, dtype=bool), axis=0)


def per_foot(estimate: GroundReactions, measured: GroundReactions, **options: Any
             ) -> dict[str, tuple[Comparison, Comparison | None, Comparison | None]]:
    """:func:`compare` foot by foot: {"right": (all frames, double support, single support), "left": ...},
    each over that foot's samples only, where it carries load (amplitudes: that foot's range over
    double support)."""
    out = {}
    for s, side in enumerate(FEET):
        ss: list = []
        a, d = compare(estimate, measured, feet=(s,), single_support=ss, loaded_only=True, **options)
        out[side] = (a, d, ss[0])
    return out
