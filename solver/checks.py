"""One shape for every check of the validation report, and the registry of its sections.

A :class:`Check` is a figure against its limit: its name, value, limit, unit, severity
(a failure decides a verdict, a warning does not), whether it passed, and what it measures —
with, where the check has them, the published source of its limit and the captured walk's own
figure. The plausibility checks (root residual, contacts), the realism checks
(``solver.realism``), the naturalness checks (``solver.naturalness``) and the MuJoCo replay
(``mjcf.validate``) all produce them.

Every section of the report — the root residual and the contacts (``solver.plausibility``),
realism, naturalness, the MuJoCo replay and simulation (``mjcf.validate``) — registers its producer
with :func:`register_check`, as an axis registers in ``solver.axes``; ``solver.plausibility.report``
runs the registered sections in their order and builds the report from what they return
(:class:`SectionResult`), listing them under ``sections`` so that a reader (the web page, the
library's manifest) shows any section without knowing it. An optional section (the MuJoCo replay,
the forward simulation) runs only when its caller asks for it. A module of checks from outside the
project registers its sections the same way; the service imports such modules by name
(``MOTIONX_CHECK_MODULES``, docs/service.md).

A check without a figure fails — a misspelt figure reads as None — unless its producer says why
there is nothing to measure (``missing``): it then passes and says so.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

Severity = Literal["failure", "warning"]


@dataclass(frozen=True)
class Check:
    """One check: ``value`` against ``limit`` (``bound`` "max": value ≤ limit, "min": value ≥
    limit). A value of None fails unless its producer says why there is nothing to measure
    (``Check.measure(missing=...)``); ``missing`` holds why there is no figure. A check that does
    not apply here (``applies`` False) passes. ``capture``: the captured walk's own figure, judged
    by the same limit."""

    name: str
    value: float | None
    limit: float
    unit: str
    what: str
    passed: bool
    severity: Severity = "failure"
    bound: Literal["max", "min"] = "max"
    source: str | None = None
    capture: float | None = None
    applies: bool = True
    missing: str | None = None

    @classmethod
    def measure(cls, name: str, value: float | None, limit: float, unit: str, what: str, *, warning: bool = False,
                at_least: bool = False, source: str | None = None, capture: float | None = None,
                applies: bool = True, missing: str | None = None) -> Check:
        """The check of ``value`` against ``limit`` (at most, or ``at_least``). ``missing``: why a
        value of None means there is nothing to measure (the check then passes); without it a
        value of None fails."""
        if value is None:
            ok = missing is not None
            why = missing if missing is not None else "no figure: not measured"
        else:
            ok = value >= limit if at_least else value <= limit
            why = None
        return cls(name, None if value is None else float(value), float(limit), unit, what, bool(ok) or not applies,
                   "warning" if warning else "failure", "min" if at_least else "max", source,
                   None if capture is None else float(capture), applies, why)

    @property
    def failed(self) -> bool:
        return self.severity == "failure" and not self.passed

    @property
    def capture_passed(self) -> bool | None:
        """Whether the captured walk's own figure is within the limit (None: no figure)."""
        if self.capture is None:
            return None
        return bool(self.capture >= self.limit if self.bound == "min" else self.capture <= self.limit)

    def to_dict(self) -> dict[str, Any]:
        """The check as the report's JSON holds it (its name is the key it is stored under)."""
        out: dict[str, Any] = {"value": self.value, "limit": self.limit, "bound": self.bound, "unit": self.unit,
                               "passed": self.passed, "severity": self.severity, "what": self.what}
        if self.source is not None:
            out["source"] = self.source
        if self.capture is not None:
            out["capture"] = self.capture
            out["capture_passed"] = self.capture_passed
        if not self.applies:
            out["applies"] = False
        if self.missing is not None:
            out["missing"] = self.missing
        return out

    def problem(self, section: str) -> str:
        """One line for the report's problems: name, figure, limit."""
        if self.value is None:
            return f"{section} {self.severity}: {self.name}: {self.missing or 'no figure, not measured'} ({self.what})"
        rel = "<" if self.bound == "min" else ">"
        return (f"{section} {self.severity}: {self.name} {self.value:.3g} {self.unit} {rel} limit {self.limit:.3g} "
                f"({self.what})")


def verdict(checks: Iterable[Check]) -> dict[str, Any]:
    """A section's verdict: its failed checks, its warnings, and passed (no failure)."""
    checks = list(checks)
    failed = [c.name for c in checks if c.failed]
    warnings = [c.name for c in checks if c.severity == "warning" and not c.passed]
    return {"failed": failed, "warnings": warnings, "passed": not failed}


@dataclass(frozen=True)
class SectionResult:
    """What a section of the report found: its checks and what it reports beside them
    (``extra``: limits, notes, figures). ``checked`` False: the motion could not be checked
    (``unchecked`` is then its ``passed``)."""

    checks: tuple[Check, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)
    checked: bool = True
    unchecked: bool | None = None

    @property
    def passed(self) -> bool | None:
        return not any(c.failed for c in self.checks) if self.checked else self.unchecked

    def to_dict(self) -> dict[str, Any]:
        """The section as the report's JSON holds it: ``extra``, ``checks`` by name, the verdict."""
        return {**self.extra, "checks": {c.name: c.to_dict() for c in self.checks}, **verdict(self.checks),
                "passed": self.passed}


@dataclass(frozen=True)
class Context:
    """What every section reads: the motion, its environment's gravity and friction, its body
    weight and leg length, the core tolerances (``solver.plausibility.Tolerances``) and each
    section's limits by section name (``limits_for``)."""

    motion: Any
    gravity: Any
    friction: float
    weight: float
    leg: float
    tolerances: Any
    limits: Mapping[str, Any] = field(default_factory=dict)

    def limits_for(self, section: str, default: Any) -> Any:
        """The caller's limits for ``section``, or the section's ``default``."""
        return self.limits.get(section, default)


@dataclass(frozen=True)
class Section:
    """A registered section of the report.

    ``name``: its key in the report; ``verdict``: the verdict its failures decide ("plausible" or
    "natural"); ``flags``: which of its checks also stand in the report's top-level ``checks``
    (name → passed, under ``prefix``): "failures" (severity failure), "all" or "none";
    ``flatten``: its ``extra`` figures stand at the report's top level (the core sections'
    figures, where readers have always found them), its checks and verdict under its name;
    ``optional``: runs only when the caller names it; ``order``: the report's order;
    ``title``: what a reader shows (default: the name, words spaced)."""

    name: str
    produce: Callable[[Context], SectionResult]
    verdict: Literal["plausible", "natural"] = "plausible"
    flags: Literal["failures", "all", "none"] = "none"
    prefix: str = ""
    flatten: bool = False
    optional: bool = False
    order: int = 0
    title: str = ""

    def describe(self) -> dict[str, Any]:
        """The section in the report's ``sections`` list: what a reader needs to show it."""
        return {"name": self.name, "title": self.title or self.name.replace("_", " "), "verdict": self.verdict,
                "optional": self.optional}

    def flag_checks(self, result: SectionResult) -> dict[str, bool]:
        """The section's checks in the report's top-level ``checks`` (name → passed)."""
        if self.flags == "none":
            return {}
        return {f"{self.prefix}{c.name}": c.passed for c in result.checks
                if self.flags == "all" or c.severity == "failure"}

    def problems(self, result: SectionResult) -> list[str]:
        """One line per failed check or warning."""
        return [c.problem(self.name) for c in result.checks if not c.passed]


_SECTIONS: dict[str, Section] = {}


def register_check(section: str, **options: Any) -> Callable[[Callable[[Context], SectionResult]],
                                                               Callable[[Context], SectionResult]]:
    """Decorator registering a section's producer: ``@register_check(section="realism", flags=...)``
    over a function ``(Context) -> SectionResult`` (options: the fields of :class:`Section`)."""
    def decorate(produce: Callable[[Context], SectionResult]) -> Callable[[Context], SectionResult]:
        if section in _SECTIONS:
            raise ValueError(f"check section {section!r} is registered twice")
        _SECTIONS[section] = Section(section, produce, **options)
        return produce
    return decorate


def sections(include: Iterable[str] = ()) -> tuple[Section, ...]:
    """The registered sections the report runs, in order: every one that is not optional, and
    the optional ones named in ``include``."""
    names = set(include)
    unknown = names - set(_SECTIONS)
    if unknown:
        raise ValueError(f"unknown check section(s) {sorted(unknown)}; registered: {sorted(_SECTIONS)}")
    return tuple(sorted((s for s in _SECTIONS.values() if not s.optional or s.name in names), key=lambda s: s.order))
