"""A balancing campaign: its runs file (RUNS.yaml) and its 1X table with a ``run`` column.

RUNS.yaml
---------
::

    planes:                      # required: every plane a weight may go on
      A: {radius_mm: 120}        # radius at which the weights sit
      B: {radius_mm: 120, holes: 12, first_hole_deg: 0}   # optional: N equally spaced holes
    reference: ref               # the run without trial weights (the "as found" run)
    runs:                        # the calibration runs: trial weights ADDED to the reference
      T1: {A: {mass_g: 5, angle_deg: 0}}
      T2: {B: {mass_g: 5, angle_deg: 90}}
    rotor_mass_kg: 40            # optional, with service_rpm: the ISO 21940-11 grade
    service_rpm: 3000
    speed_tolerance_rpm: 30      # optional: a run's speed matched to the reference's within this
    disk_mass_kg: {A: 20}        # optional: the model-based unbalance (one run-up, no trial weight)

**Angles** of the weights are measured in the same sense as the phase of the table
(field practice, ``--phase lag``: both *against* the rotation, from the keyphasor mark;
``--phase lead``: both with it).  A weight of ``m`` g at radius ``R`` mm and angle
``theta`` is the complex unbalance ``m R e^{-i theta}`` g·mm in the package's (lead)
convention for ``lag`` and ``m R e^{+i theta}`` for ``lead`` — the same map
:func:`~rotor_env.measurements.vectors.from_phase` applies to the vectors, so a weight
turned by ``d`` degrees turns an isotropic rotor's response by ``d`` degrees of phase.

The table
---------
The ``diagnose --vectors`` format (:func:`~rotor_env.measurements.vectors.load_vector_table`)
plus a ``run`` column.  Several rows of one run at one speed are repeat acquisitions:
their mean is the run's vector, their scatter its uncertainty.  A run's speeds are
matched to the reference's within ``speed_tolerance_rpm`` (default 2 % of the speed).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..measurements.vectors import VectorTable, VectorTableError, from_phase, load_vector_table

__all__ = ["BalanceData", "BalanceError", "Campaign", "Plane", "load_campaign", "read_balance_table",
           "stack_tables"]

_TOP_KEYS = {"planes", "reference", "runs", "rotor_mass_kg", "service_rpm", "speed_tolerance_rpm", "disk_mass_kg"}
_PLANE_KEYS = {"radius_mm", "holes", "first_hole_deg"}


class BalanceError(ValueError):
    """A balancing campaign (runs file or table) that cannot be used as it is."""


@dataclass(frozen=True)
class Plane:
    """A correction plane: the radius of its weights and, optionally, its holes."""

    name: str
    radius_mm: float
    holes: int | None = None
    first_hole_deg: float = 0.0


@dataclass(frozen=True)
class Campaign:
    """A validated RUNS.yaml: planes, the reference run and the trial weights of each run.

    ``weights[run][plane] = (mass_g, angle_deg)``; the reference has none.
    """

    planes: tuple[Plane, ...]
    reference: str
    weights: dict[str, dict[str, tuple[float, float]]]
    rotor_mass_kg: float | None = None
    service_rpm: float | None = None
    speed_tolerance_rpm: float | None = None
    disk_mass_kg: dict[str, float] = field(default_factory=dict)
    source: str = ""

    @property
    def plane_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.planes)

    @property
    def runs(self) -> tuple[str, ...]:
        """The reference first, then the calibration runs in file order."""
        return (self.reference, *tuple(r for r in self.weights if r != self.reference))

    def trial_matrix(self, phase: str = "lag") -> np.ndarray:
        """(runs, planes) complex trial unbalance in g·mm (lead convention), reference row zero."""
        W = np.zeros((len(self.runs), len(self.planes)), dtype=complex)
        for k, run in enumerate(self.runs):
            for j, p in enumerate(self.planes):
                if p.name in self.weights.get(run, {}):
                    m, ang = self.weights[run][p.name]
                    W[k, j] = complex(from_phase(np.array(m * p.radius_mm), np.array(ang), phase))
        return W


def _number(value, where: str, *, positive: bool = False, non_negative: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise BalanceError(f"{where}: {value!r} is not a finite number")
    if positive and value <= 0:
        raise BalanceError(f"{where}: {value!r} must be positive")
    if non_negative and value < 0:
        raise BalanceError(f"{where}: {value!r} must not be negative")
    return float(value)


def load_campaign(path: str | os.PathLike) -> Campaign:
    """Read and validate RUNS.yaml (or .json); every error names the file and the key."""
    import json

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BalanceError(f"{path}: cannot read the runs file ({exc})") from None
    if path.suffix.lower() == ".json":
        try:
            raw = json.loads(text)
        except json.JSONDecodeError as exc:
            raise BalanceError(f"{path}: not valid JSON ({exc})") from None
    else:
        import yaml

        try:
            raw = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise BalanceError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(raw, dict):
        raise BalanceError(f"{path}: expected a mapping with keys planes, reference, runs")
    unknown = sorted(set(map(str, raw)) - _TOP_KEYS)
    if unknown:
        raise BalanceError(f"{path}: unknown key(s) {unknown} (known: {sorted(_TOP_KEYS)})")
    planes_raw = raw.get("planes")
    if not isinstance(planes_raw, dict) or not planes_raw:
        raise BalanceError(f"{path}: key 'planes' is missing or empty: say which correction planes exist, "
                           "e.g. planes: {A: {radius_mm: 100}}")
    planes = []
    for name, spec in planes_raw.items():
        where = f"{path}: planes.{name}"
        if not isinstance(spec, dict):
            raise BalanceError(f"{where}: expected a mapping with radius_mm, got {spec!r}")
        bad = sorted(set(map(str, spec)) - _PLANE_KEYS)
        if bad:
            raise BalanceError(f"{where}: unknown key(s) {bad} (known: {sorted(_PLANE_KEYS)})")
        if "radius_mm" not in spec:
            raise BalanceError(f"{where}.radius_mm is missing: the radius of the weights")
        radius = _number(spec["radius_mm"], f"{where}.radius_mm", positive=True)
        holes = spec.get("holes")
        if holes is not None and (isinstance(holes, bool) or not isinstance(holes, int) or holes < 2):
            raise BalanceError(f"{where}.holes: {holes!r} is not a whole number >= 2")
        first = _number(spec.get("first_hole_deg", 0.0), f"{where}.first_hole_deg")
        planes.append(Plane(str(name), radius, holes, first))
    names = [p.name for p in planes]
    ref = raw.get("reference")
    if ref is None or isinstance(ref, dict | list):
        raise BalanceError(f"{path}: key 'reference' is missing: the run without trial weights, e.g. reference: ref")
    ref = str(ref)
    runs_raw = raw.get("runs")
    if not isinstance(runs_raw, dict) or not runs_raw:
        raise BalanceError(f"{path}: key 'runs' is missing or empty: the calibration runs and their trial weights")
    weights: dict[str, dict[str, tuple[float, float]]] = {}
    for run, spec in runs_raw.items():
        run = str(run)
        where = f"{path}: runs.{run}"
        if run == ref:
            if spec:
                raise BalanceError(f"{where}: the reference run carries no trial weight (weights are relative to it)")
            continue
        if not isinstance(spec, dict) or not spec:
            raise BalanceError(f"{where}: expected {{PLANE: {{mass_g, angle_deg}}}}, got {spec!r}")
        weights[run] = {}
        for plane, w in spec.items():
            plane = str(plane)
            if plane not in names:
                raise BalanceError(f"{where}.{plane}: unknown plane {plane!r} (planes: {names})")
            if not isinstance(w, dict):
                raise BalanceError(f"{where}.{plane}: expected {{mass_g, angle_deg}}, got {w!r}")
            for key in ("mass_g", "angle_deg"):
                if key not in w:
                    raise BalanceError(f"{where}.{plane}.{key} is missing" + (
                        " (weight angles are measured like the phase: against rotation from the keyphasor "
                        "for --phase lag)" if key == "angle_deg" else ""))
            bad = sorted(set(map(str, w)) - {"mass_g", "angle_deg"})
            if bad:
                raise BalanceError(f"{where}.{plane}: unknown key(s) {bad}")
            weights[run][plane] = (_number(w["mass_g"], f"{where}.{plane}.mass_g", positive=True),
                                   _number(w["angle_deg"], f"{where}.{plane}.angle_deg"))
    if not weights:
        raise BalanceError(f"{path}: no calibration run (a run with a trial weight) in 'runs'")
    opt = {}
    for key in ("rotor_mass_kg", "service_rpm", "speed_tolerance_rpm"):
        if raw.get(key) is not None:
            opt[key] = _number(raw[key], f"{path}: {key}", positive=True)
    if ("rotor_mass_kg" in opt) != ("service_rpm" in opt):
        raise BalanceError(f"{path}: the ISO 21940-11 grade needs both rotor_mass_kg and service_rpm")
    disk = {}
    for plane, m in (raw.get("disk_mass_kg") or {}).items():
        if str(plane) not in names:
            raise BalanceError(f"{path}: disk_mass_kg.{plane}: unknown plane {plane!r} (planes: {names})")
        disk[str(plane)] = _number(m, f"{path}: disk_mass_kg.{plane}", positive=True)
    return Campaign(tuple(planes), ref, weights, disk_mass_kg=disk, source=str(path), **opt)


@dataclass(frozen=True)
class BalanceData:
    """The table reduced to one mean vector per run, speed and probe.

    ``Y[k, s, p]``: mean 1X vector (lead convention, table unit) of run ``campaign.runs[k]``
    at ``rpm[s]`` on probe ``p``; ``var[k, s, p]``: the variance of that mean,
    ``E|Y - true|^2`` (complex, circular), from the pooled scatter of the repeats at that
    speed and probe (NaN where unknown); ``n[k, s, p]`` the repeats averaged;
    ``dof``: the smallest real degrees of freedom of a cell's pooled scatter (0: no repeats
    anywhere), ``cell_dof[s, p]`` each cell's: ``2 sum_k (n_k - 1)``, two per complex residual,
    as the noise is circular (its real and imaginary parts each carry half the variance);
    ``run_rpm[k, s]``: the mean speed of run ``k``'s rows matched to ``rpm[s]``.
    """

    rpm: np.ndarray
    probes: tuple[str, ...]
    runs: tuple[str, ...]
    Y: np.ndarray
    var: np.ndarray
    n: np.ndarray
    dof: int
    amp_unit: str
    source: str
    notes: tuple[str, ...] = ()
    run_rpm: np.ndarray | None = None
    cell_dof: np.ndarray | None = None


def read_balance_table(path: str | os.PathLike, campaign: Campaign, *, amp_unit: str = "um", phase: str = "lag",
                       run_column: str = "run") -> BalanceData:
    """Read the table, group its rows by run and speed, and pool the repeats' scatter."""
    try:
        table = load_vector_table(path, amp_unit=amp_unit, phase=phase, run_column=run_column)
    except VectorTableError as exc:
        raise BalanceError(str(exc)) from None
    return group_table(table, campaign)


def group_table(table: VectorTable, campaign: Campaign) -> BalanceData:
    """:func:`read_balance_table` on a table already read (``table.runs`` set)."""
    src = table.source
    if table.runs is None:
        raise BalanceError(f"{src}: the table has no run column")
    labels = np.array(table.runs)
    lines = np.array(table.lines if table.lines is not None else np.arange(len(labels)) + 2)
    declared = set(campaign.runs)
    for lab, line in zip(labels, lines, strict=True):
        if lab not in declared:
            raise BalanceError(f"{src}, line {line}, column 'run': run {lab!r} is not in {campaign.source} "
                               f"(runs: {list(campaign.runs)})")
    for run in campaign.runs:
        if run not in set(labels):
            key = "reference" if run == campaign.reference else f"runs.{run}"
            raise BalanceError(f"{campaign.source}: {key}: run {run!r} has no row in {src} "
                               f"(its run column holds {sorted(set(labels))})")
    rpm = table.rpm
    Y1 = table.vectors[1]
    # the reference's speeds: clusters of its rows within the tolerance
    ref_rows = labels == campaign.reference
    ref_speeds = _cluster(rpm[ref_rows], campaign.speed_tolerance_rpm)
    P = len(table.probes)
    K, S = len(campaign.runs), len(ref_speeds)
    groups: dict[tuple[int, int], list[int]] = {}
    notes = []
    for r in range(len(rpm)):
        k = campaign.runs.index(labels[r])
        s = int(np.argmin(np.abs(ref_speeds - rpm[r])))
        tol = _tolerance(ref_speeds[s], campaign.speed_tolerance_rpm)
        if abs(rpm[r] - ref_speeds[s]) > tol:
            notes.append(f"line {lines[r]}: run {labels[r]!r} at {rpm[r]:.0f} rpm matches no speed of the reference "
                         f"within {tol:.0f} rpm: left out")
            continue
        groups.setdefault((k, s), []).append(r)
    missing = [(campaign.runs[k], ref_speeds[s]) for k in range(K) for s in range(S) if (k, s) not in groups]
    keep_s = [s for s in range(S) if all((k, s) in groups for k in range(K))]
    if missing:
        notes.append("speeds not measured in every run are left out: " + ", ".join(
            f"{run} at {sp:.0f} rpm" for run, sp in missing[:6]) + (" ..." if len(missing) > 6 else ""))
    if not keep_s:
        raise BalanceError(f"{src}: no speed of the reference run {campaign.reference!r} "
                           f"({', '.join(f'{v:.0f}' for v in ref_speeds)} rpm) was measured in every run "
                           f"(missing: {', '.join(f'{r} at {v:.0f} rpm' for r, v in missing[:6])}); "
                           "set speed_tolerance_rpm in the runs file if the speeds differ a little")
    S2 = len(keep_s)
    Y = np.zeros((K, S2, P), dtype=complex)
    n = np.zeros((K, S2, P), dtype=int)
    run_rpm = np.zeros((K, S2))
    ss = np.zeros((S2, P))
    dof = np.zeros((S2, P), dtype=int)
    for si, s in enumerate(keep_s):
        for k in range(K):
            rows = groups[(k, s)]
            v = Y1[rows]
            Y[k, si] = v.mean(axis=0)
            n[k, si] = len(rows)
            run_rpm[k, si] = float(np.mean(rpm[rows]))
            ss[si] += np.sum(np.abs(v - v.mean(axis=0)) ** 2, axis=0)
            dof[si] += len(rows) - 1
    with np.errstate(invalid="ignore", divide="ignore"):
        pooled = np.where(dof > 0, ss / np.maximum(dof, 1), np.nan)  # E|x - mean|^2 of one acquisition
    zero = (dof > 0) & (pooled <= 0)
    if zero.any():
        si, p = np.argwhere(zero)[0]
        raise BalanceError(f"{src}: the repeats at {ref_speeds[keep_s[si]]:.0f} rpm on probe {table.probes[p]!r} are "
                           "identical in every run (no scatter): copied rows, not independent acquisitions; give "
                           "one row per run and speed, or the real repeats")
    var = pooled[None] / n
    return BalanceData(np.asarray(ref_speeds)[keep_s], table.probes, campaign.runs, Y, var, n,
                       2 * int(dof.min()) if dof.size else 0, table.amp_unit, src, tuple(notes), run_rpm,
                       2 * dof)


def _tolerance(rpm: float, tol: float | None) -> float:
    return tol if tol is not None else max(0.02 * rpm, 1.0)


def _cluster(rpm: np.ndarray, tol: float | None) -> np.ndarray:
    """Speeds of the reference: sorted rows joined while within the tolerance of the group's first."""
    out: list[list[float]] = []
    for v in np.sort(rpm):
        if out and v - out[-1][0] <= _tolerance(out[-1][0], tol):
            out[-1].append(float(v))
        else:
            out.append([float(v)])
    return np.array([np.mean(g) for g in out])


def stack_tables(out: str | os.PathLike, tables: dict[str, str | os.PathLike | list], *,
                 overwrite: bool = False) -> Path:
    """Join vector tables (``diagnose --vectors`` CSVs: one file or a list of files per run)
    into one with a ``run`` column."""
    import csv

    from ..measurements.files import csv_dialect
    from ..outputs import atomic_write

    header = None
    rows: list[list[str]] = []
    pairs = [(run, p) for run, ps in tables.items() for p in (ps if isinstance(ps, list | tuple) else [ps])]
    for run, path in pairs:
        # each file in its own dialect (semicolons, a decimal comma), written out as plain CSV
        dialect = csv_dialect(path)
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh, delimiter=dialect.delimiter)
            head = [h.strip() for h in next(reader)]
            if header is None:
                header = head
            elif head != header:
                raise BalanceError(f"{path}: columns {head} differ from the first table's {header}")
            rows += [[run, *(c.replace(",", ".") if dialect.decimal == "," else c for c in r)]
                     for r in reader if r and any(c.strip() for c in r)]

    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["run"] + (header or []))
            w.writerows(rows)

    return atomic_write(Path(out), write, overwrite=overwrite)
