"""Compare a model with measurements: equation-error fit and free-run output error."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from identifier import RecursiveQR
from identifier.hac import hac_covariance, wald_test

from ..effects import EFFECTS, PHYSICAL_EFFECTS
from ..measurements import Measurements
from ..params import RotorParams
from ..regression import ColumnCache, RegressionSpec, regression_arrays
from ..simulator import SimulationError, free_run


# ------------------------------------------------------------------ comparison
@dataclass
class Comparison:
    """A model fitted to measurements and compared with them."""

    model: tuple[str, ...]
    columns: tuple[str, ...]
    coefficients: np.ndarray
    standard_errors: np.ndarray
    physical: dict[str, float]
    energy: float              # equation-error residual energy J
    rms: float                 # equation-error residual RMS
    r2: float
    n_rows: int
    n_params: int
    fit_x: float
    fit_y: float
    fit_bands: list[dict]
    significance: dict[str, dict]
    residual: np.ndarray = field(repr=False)
    onsets: dict[str, float] = field(default_factory=dict)
    splits: tuple[str, ...] = ()           # effects with onsets whose value changes (not appears)
    physical_before: dict[str, float] = field(default_factory=dict)  # their values before
    simulated: Measurements | None = field(repr=False, default=None)
    diverged: bool = False
    covariance: np.ndarray | None = field(repr=False, default=None)  # HAC, when robust
    #: errors-in-variables bias removed from the coefficients (naive minus corrected; None: not corrected)
    eiv_bias: np.ndarray | None = field(repr=False, default=None)

    @property
    def fit_percent(self) -> float:
        return 0.5 * (self.fit_x + self.fit_y)

    def coefficient_dict(self) -> dict[str, float]:
        return {c: float(v) for c, v in zip(self.columns, self.coefficients, strict=True)}


def _fit_percent(meas: np.ndarray, model: np.ndarray) -> float:
    den = np.linalg.norm(meas - meas.mean())
    if den == 0:
        return 0.0
    return float(max(-100.0, 100.0 * (1.0 - np.linalg.norm(meas - model) / den)))


def _model_params(
    model: Sequence[str], physical: dict[str, float], ip: float, known: dict, absent: Iterable[str] = ()
) -> RotorParams:
    """A simulatable rotor from identified physical parameters (absent effects = 0).

    Every physical effect is in the rotor (those not in the model with their known
    values, else 0 — the stiffness scale 1); the paper's ``unbalance_in_phase``
    replaces ``unbalance`` when the model uses it (they share ``tau``).
    """
    base = tuple(e for e in PHYSICAL_EFFECTS if not (e == "unbalance" and "unbalance_in_phase" in model))
    effects = tuple(dict.fromkeys((*base, *model)))
    values: dict[str, float] = {}
    for e in effects:
        for p in EFFECTS[e].parameters:
            if e in absent:
                v = 0.0
            elif e in model:
                v = physical.get(p.name, 0.0)
            elif e in known:
                v = known[e][p.name]
            else:
                v = 1.0 if p.name == "k" else 0.0
            # identified values where the equations are undefined (c < 0) are clipped to
            # their domain so the free run can be simulated
            values[p.name] = p.clip_to_domain(v)
    return RotorParams(ip=ip, values=values, effects=effects)


def _bands(speed: np.ndarray, n: int = 6) -> list[tuple[float, float]]:
    lo, hi = float(speed.min()), float(speed.max())
    if hi <= lo:
        return [(lo, hi)]
    edges = np.linspace(lo, hi, n + 1)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


#: the prefilter passes rotation orders up to this multiple of the top speed undistorted enough
#: for the non-linear columns (products of a 1x response and the 2x spin reach 3x; and at
#: least this many radians per time unit: the natural frequency is 1)
PREFILTER_ORDERS = 10.0


#: channel noise below this fraction of the peak inclination is not worth a prefilter
NOISE_DETECTION = 1e-4


def white_noise_level(x: np.ndarray) -> float:
    """White-noise standard deviation of a sampled channel (third differences: a smooth
    signal vanishes in them, white noise grows by sqrt(20))."""
    d = np.diff(x, 3)
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / math.sqrt(20.0)) if len(d) else 0.0


def prefilter_cutoff(speed: np.ndarray, dt: float) -> float | None:
    """Cut-off (cycles per time unit) of the noise prefilter, or None when it gains little.

    The rotor's response lives below ``PREFILTER_ORDERS`` x the top spin speed (orders up
    to 3, whirls near the natural frequency); white sensor noise spreads to the Nyquist
    frequency.  Removing it before the regression is what keeps the errors-in-variables
    bias of ``c`` and ``h`` small: the dry-friction column ``v/|v|`` is non-linear in
    the noisy rates, and near break-away ``|v|`` is comparable to the noise.
    """
    top = max(PREFILTER_ORDERS * float(np.max(np.abs(speed))), PREFILTER_ORDERS)
    fc = top / (2.0 * math.pi)
    return fc if fc < 0.2 / dt else None


class WindowData:
    """Measurements restricted to the informative window, prefiltered, with caches.

    ``raw`` keeps the unfiltered samples of the window (the noise floor is read from
    them); ``data``/``meas`` are the prefiltered ones every fit uses.  ``noise_gain``
    is the factor by which the prefilter scales white noise's RMS (1 without it).
    """

    def __init__(self, meas: Measurements, ip: float, equation: str, window_fraction: float,
                 t_start: float | None, prefilter: bool = True):
        from scipy.signal import butter, sosfiltfilt

        self.full = meas
        amp = np.hypot(meas.theta_x, meas.theta_y)
        if t_start is None:
            peak = float(amp.max())
            k0 = int(np.argmax(amp > window_fraction * peak)) if peak > 0 else 0
            t_start = float(meas.t[k0])
        self.t_start = t_start
        self.raw = meas.slice_time(t_start, None)
        if len(self.raw) < 20:
            raise ValueError(f"only {len(self.raw)} samples after t = {t_start:g}: too few to diagnose")
        dt = float(np.median(np.diff(meas.t)))
        # the prefilter is for sensor noise: a record without any (a simulation) keeps its samples
        noisy = white_noise_level(meas.theta_x) + white_noise_level(meas.theta_y) > NOISE_DETECTION * float(amp.max())
        #: the record carries sensor noise (a simulation without noise does not)
        self.noisy = bool(noisy)
        self.cutoff = prefilter_cutoff(meas.phi_dot, dt) if prefilter and noisy and len(meas) > 60 else None
        self.noise_gain = 1.0
        self.sos = None
        # each inclination channel's white-noise level (the errors-in-variables correction adds more)
        self.channel_noise = np.array([white_noise_level(meas.data[:, j]) for j in range(4, 10)]) if noisy else None
        self.window_start = int(np.argmax(meas.t >= t_start))
        filtered = meas
        if self.cutoff is not None:
            sos = butter(4, self.cutoff, fs=1.0 / dt, output="sos")
            self.sos = sos
            out = meas.data.copy()
            out[:, 4:] = sosfiltfilt(sos, out[:, 4:], axis=0)  # the six inclination channels
            filtered = Measurements(out, meas.source)
            impulse = np.zeros(4001)
            impulse[2000] = 1.0
            self.noise_gain = float(np.linalg.norm(sosfiltfilt(sos, impulse)))
        self.meas = filtered.slice_time(t_start, None)
        self.ip = ip
        #: 95 % half-width of an ip estimated from the data (0: ip given)
        self.ip_uncertainty = 0.0
        self.equation = equation
        self.raw_data = np.ascontiguousarray(self.raw.data)
        self.raw_columns: ColumnCache = {}  # each effect's columns on raw_data
        self.data = np.ascontiguousarray(self.meas.data)
        #: the scanned parameters' values the models are built with (effect -> {name: value}):
        #: set by the candidate scan (:func:`.candidates._scan_parameters`), defaults elsewhere
        self.scanned: dict[str, dict[str, float]] = {}

    @property
    def data(self) -> np.ndarray:
        """The window's samples (ten-column layout)."""
        return self._data

    @data.setter
    def data(self, value: np.ndarray) -> None:
        # each effect's columns on these samples (every model tried reuses them); new
        # samples (the errors-in-variables replicates' view) start a new cache
        self._data = value
        self.columns: ColumnCache = {}
        #: the latest models' designs on these samples (:func:`model_design`)
        self.designs: dict[str, tuple] = {}
        #: (effect, onset, scanned values) -> the order spectrum of its columns (the evidence)
        self.order_profiles: dict[str, np.ndarray] = {}
        #: (effect, scanned value) -> the share of samples where the effect acts there (the
        #: scan's activity test depends on the data alone, not on the model it is added to)
        self.active_share: dict[tuple[str, float], float] = {}


def model_design(data: WindowData, model: Sequence[str], known: dict, onsets: dict[str, float],
            splits: Iterable[str] = (), *, raw: bool = False):
    """``spec, X, y, t_rows, columns, groups`` of a model (``raw``: on the unfiltered samples).

    An effect with an onset is zero before it (it *appears*); if it is also in
    ``splits`` it has its own coefficients before the onset (its value *changes*, a
    crack that grows), in extra columns named ``<coefficient>_before``.
    """
    # ranking a candidate fits, tests and scans the same model: its design is built once
    # (read-only: the callers share it), the latest few kept per data set
    key = repr((tuple(model), known or {}, dict(onsets), tuple(splits), raw, getattr(data, "scanned", {}), data.ip))
    hit = data.designs.get(key)
    if hit is not None:
        return hit
    out = _build_design(data, model, known, onsets, splits, raw)
    for a in out[1:3]:
        a.setflags(write=False)
    if len(data.designs) >= 3:
        data.designs.pop(next(iter(data.designs)))
    data.designs[key] = out
    return out


def _build_design(data: WindowData, model: Sequence[str], known: dict, onsets: dict[str, float],
                  splits: Iterable[str], raw: bool):
    spec = RegressionSpec(effects=tuple(model), equation=data.equation, known=known or {},
                          scanned=getattr(data, "scanned", {}))
    X, y = regression_arrays(spec, data.raw_data if raw else data.data, data.ip,
                             cache=data.raw_columns if raw else data.columns)
    t_rows = np.repeat(data.meas.t, spec.rows_per_sample)
    columns, groups, extra = list(spec.columns), dict(spec.groups), []
    for e, tc in onsets.items():
        cols = [spec.columns.index(c) for c in spec.groups[e]]
        before = t_rows < tc
        if e in splits:
            extra.append(X[:, cols] * before[:, None])
            names = tuple(f"{c}_before" for c in spec.groups[e])
            columns += names
            groups[f"{e}_before"] = names
        X[np.ix_(before, cols)] = 0.0
    if extra:
        X = np.hstack([X, *extra])
    return spec, X, y, t_rows, tuple(columns), groups


def physical_values(spec: RegressionSpec, columns: Sequence[str], coef: np.ndarray,
                     splits: Sequence[str]) -> tuple[dict[str, float], dict[str, float]]:
    """Physical parameters of the coefficients, and (for split effects) their values before."""
    n = spec.n_columns
    physical = spec.physical(coef[:n])
    physical_before: dict[str, float] = {}
    if splits:
        theta_b = coef[:n].copy()
        for e in splits:
            for c in spec.groups[e]:
                theta_b[spec.columns.index(c)] = coef[list(columns).index(f"{c}_before")]
        pb = spec.physical(theta_b)
        physical_before = {p.name: pb[p.name] for e in splits for p in EFFECTS[e].parameters}
    return physical, physical_before


def compare(
    data: WindowData,
    model: Sequence[str],
    known: dict | None = None,
    onsets: dict[str, float] | None = None,
    splits: Iterable[str] = (),
    *,
    simulate: bool = True,
    robust: bool = False,
    alpha: float = 0.05,
) -> Comparison:
    """Fit ``model`` (equation error) and, with ``simulate``, run it free (output error).

    With ``robust`` the standard errors and the effect tests are the HAC (Newey–West)
    ones of :mod:`identifier.hac`, valid on an autocorrelated residual; without it they
    are the classical ones (cheaper: used while ranking, never reported).
    """
    onsets = dict(onsets or {})
    splits = tuple(e for e in splits if e in onsets)
    spec, X, y, _, columns, groups = model_design(data, model, known or {}, onsets, splits)
    _check_finite_rows(data, X, y, spec.rows_per_sample)
    est = RecursiveQR(columns=columns, groups=groups).fit(X, y)
    coef = est.coefficients()
    with np.errstate(over="ignore", invalid="ignore"):
        resid = y - X @ coef
        J = float(resid @ resid)
        tss = float(np.sum((y - y.mean()) ** 2))
    if not (np.isfinite(coef).all() and math.isfinite(J) and math.isfinite(tss)):
        r = int(np.argmax(~np.isfinite(resid) | (np.abs(resid) == np.abs(resid).max())))
        raise ValueError(f"{data.full.source}: the fit of {', '.join(model)} is not finite (residual energy {J:.3g}): "
                         f"the values near t = {float(data.meas.t[r // spec.rows_per_sample]):.6g} overflow the model's "
                         "numbers")
    physical, physical_before = physical_values(spec, columns, coef, splits)
    sig = est.effect_tests().to_dict()
    comp = Comparison(
        model=tuple(model), columns=columns, coefficients=coef, standard_errors=est.standard_errors(),
        physical=physical, energy=J, rms=math.sqrt(J / len(y)), r2=1.0 - J / tss if tss > 0 else 0.0,
        n_rows=len(y), n_params=int(est.identifiable().sum()), fit_x=float("nan"), fit_y=float("nan"),
        fit_bands=[], significance=sig, residual=resid, onsets=onsets, splits=splits,
        physical_before=physical_before,
    )
    if robust:
        _robust_statistics(comp, X, groups, alpha, spec.rows_per_sample)
    if simulate:
        _free_run(comp, data, spec.known)
    return comp


def _check_finite_rows(data: WindowData, X: np.ndarray, y: np.ndarray, per: int) -> None:
    """Every regression row finite, and small enough that its square is (the energies)."""
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(X).all() and np.isfinite(y).all() and np.abs(X).max(initial=0.0) <= 1e150 \
                and np.abs(y).max(initial=0.0) <= 1e150:
            return  # the usual case, without the per-row reductions
        bad = ~(np.isfinite(X).all(axis=1) & np.isfinite(y)) | (np.abs(y) > 1e150) | (np.abs(X) > 1e150).any(axis=1)
    if bad.any():
        r = int(np.argmax(bad))
        raise ValueError(f"{data.full.source}: the model's regression is not finite at t = "
                         f"{float(data.meas.t[r // per]):.6g}{_culprit(data)}: a value overflows the effects' "
                         "products; check it")


def _culprit(data: WindowData) -> str:
    """Where the record holds a value beyond 1e100 (the prefilter spreads it over its neighbours)."""
    from ..measurements import COLUMNS

    full = data.full.data
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(full) | (np.abs(full) > 1e100)
    if not bad.any():
        return ""
    r, c = (int(i) for i in np.argwhere(bad)[0])
    return f" (from sample {r} of the record, t = {float(full[r, 0]):.6g}: {COLUMNS[c]} = {float(full[r, c])!r})"


def make_robust(data: WindowData, comp: Comparison, alpha: float = 0.05) -> Comparison:
    """Replace ``comp``'s standard errors and effect tests by the HAC ones (in place)."""
    spec, X, _, _, _, groups = model_design(data, comp.model, known_values(comp.model), comp.onsets, comp.splits)
    _robust_statistics(comp, X, groups, alpha, spec.rows_per_sample)
    return comp


def _robust_statistics(comp: Comparison, X: np.ndarray, groups: dict[str, tuple[str, ...]],
                       alpha: float = 0.05, rows_per_time: int = 1) -> None:
    """HAC standard errors and effect-last Wald tests (see :mod:`identifier.hac`)."""
    cols = list(comp.columns)
    keep = np.flatnonzero(np.linalg.norm(X, axis=0) > 0)  # columns zero throughout: no estimate
    cov = np.zeros((len(cols), len(cols)))
    if keep.size:
        cov[np.ix_(keep, keep)] = hac_covariance(X[:, keep], comp.residual, rows_per_time=rows_per_time)
    comp.covariance = cov
    comp.standard_errors = np.sqrt(np.maximum(np.diag(cov), 0.0))
    sig = {}
    for name, group in groups.items():
        idx = [cols.index(c) for c in group if cols.index(c) in set(keep.tolist())]
        if not idx:
            sig[name] = {"F": 0.0, "df_num": 0.0, "df_den": float(comp.n_rows), "p_value": 1.0,
                         "log10_p": 0.0, "testable": False, "significant": False}
            continue
        F, lp = wald_test(comp.coefficients[idx], cov[np.ix_(idx, idx)])
        sig[name] = {"F": F, "df_num": float(len(idx)), "df_den": float(comp.n_rows - comp.n_params),
                     "p_value": float(10.0**lp), "log10_p": lp, "testable": True,
                     "significant": bool(lp < math.log10(alpha)), "test": "HAC Wald"}
    comp.significance = sig


def _free_run(comp: Comparison, data: WindowData, known: dict) -> None:
    """Output-error simulation, split where an effect appears (it is absent before)."""
    m = data.meas
    cuts = sorted({tc for tc in comp.onsets.values() if m.t[0] < tc < m.t[-1]})
    bounds = [0, *(int(np.searchsorted(m.t, tc)) for tc in cuts), len(m) - 1]
    state = (m.theta_x[0], m.theta_y[0], m.theta_x_dot[0], m.theta_y_dot[0])
    pieces = []
    try:
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if b <= a:
                continue
            pending = {e for e, tc in comp.onsets.items() if tc > m.t[a]}
            # before its onset an effect is absent, or has its own values if it changes
            physical = {**comp.physical, **{k: v for k, v in comp.physical_before.items()}} \
                if pending & set(comp.splits) else comp.physical
            try:
                params = _model_params(comp.model, physical, data.ip, known, pending - set(comp.splits))
            except ValueError:
                # coefficients no physical rotor has (a breathing term without a mean crack
                # stiffness: infinite depth): the model cannot be run, it is not a candidate
                raise SimulationError("the fitted coefficients are not a physical rotor") from None
            # compiled once for the whole registry: every candidate model shares the kernel
            seg = free_run(params, m.t[a : b + 1], m.phi[a : b + 1], m.phi_dot[a : b + 1], state,
                           compiled_for=tuple(EFFECTS))
            pieces.append(seg.data if not pieces else seg.data[1:])
            state = tuple(seg.data[-1, 4:8])
    except SimulationError:
        comp.diverged = True
        comp.fit_x = comp.fit_y = -100.0
        return
    sim = Measurements(np.vstack(pieces))
    comp.simulated = sim
    comp.fit_x = _fit_percent(m.theta_x, sim.theta_x)
    comp.fit_y = _fit_percent(m.theta_y, sim.theta_y)
    bands = []
    for lo, hi in _bands(m.phi_dot):
        sel = (m.phi_dot >= lo) & (m.phi_dot <= hi)
        if sel.sum() < 10:
            continue
        fx = _fit_percent(m.theta_x[sel], sim.theta_x[sel])
        fy = _fit_percent(m.theta_y[sel], sim.theta_y[sel])
        bands.append({"speed_min": lo, "speed_max": hi, "fit_percent": 0.5 * (fx + fy)})
    comp.fit_bands = bands


def known_values(model: Iterable[str], k: float = 1.0) -> dict:
    return {} if "stiffness" in model else {"stiffness": {"k": k}}
