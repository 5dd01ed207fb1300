"""What the field plots draw, computed: order-tracked vectors, whirl frequencies and peaks,
the on-line identifier's parameter tracks and the monitor's alarms.

The figures (:mod:`rotor_env.plots`) take these numbers and draw them; nothing here draws.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..effects import whirl_effects
from ..measurements.vectors import order_map, order_track
from .synchronous import SynchronousModel, whirl_branches

__all__ = ["ParameterTracks", "monitor_alarms", "order_vectors", "parameter_tracks", "whirl_frequencies",
           "whirl_peaks"]


# ------------------------------------------------------------------ order tracking
def order_vectors(
    t: np.ndarray, x: np.ndarray, phi: np.ndarray, orders: Sequence[int] = (1,), revolutions: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, dict[int, np.ndarray]]:
    """Per-revolution order-tracked vectors: ``(t_mid, speed, {order: X})``.

    :func:`rotor_env.measurements.vectors.order_track` with ``method="lstsq"``: between
    consecutive keyphasor marks (``phi`` a multiple of ``2 pi``, every ``revolutions``
    turns) the samples are fitted by least squares with a constant and the ``orders``: a
    real channel as ``x ≈ a0 + sum_n Re(X_n e^{i n phi})`` (the lead convention), a complex
    one (``z = th_y + i th_x``) as ``z ≈ a0 + sum_n X_n e^{i n phi}`` with signed orders
    (``-1``: backward).  The fit uses the sampled ``phi`` itself, so an accelerating shaft
    (samples not uniform in angle) is exact for a signal made of these orders; each sample
    weighted by the angle it covers, it is otherwise the DFT against ``phi`` (orders not
    fitted leak in only to the trapezoid's accuracy).  ``speed`` is the mean speed of each
    revolution, ``2 pi revolutions / (t_b - t_a)`` in rad per time unit; ``t_mid`` the
    middle of it.  A block with too few samples gives NaN.
    """
    track = order_track(t, x, phi, tuple(orders), revolutions, method="lstsq")
    return track.t, track.speed, track.vectors



# ------------------------------------------------------------------ whirl
def _whirl_model_effects() -> tuple[str, ...]:
    """The fixed-frame effects of :func:`whirl_frequencies` after the implicit stiffness: those
    declared ``whirl=True`` (:attr:`rotor_env.effects.Effect.whirl`)."""
    return tuple(e for e in whirl_effects() if e != "stiffness")


def whirl_frequencies(
    speed: np.ndarray,
    stiffness: float,
    damping: float,
    ip: float,
    anisotropy: float = 0.0,
    cross_coupling: float = 0.0,
    others: Mapping[str, Sequence[float]] | None = None,
) -> dict[str, np.ndarray]:
    """Damped natural (whirl) frequencies of the linear fixed-frame rotor at each speed.

    The model (docs/PHYSICS.md 1.4, the fault library's fixed-frame effects)::

        th_y'' + ip phid th_x' + c th_y' + (k + delta) th_y + q th_x = 0
        th_x'' - ip phid th_y' + c th_x' + (k - delta) th_x - q th_y = 0

    i.e. ``z'' - i ip phid z' + c z' + k z + delta conj(z) - i q z = 0`` with ``stiffness``
    ``k``, ``damping`` ``c``, ``anisotropy`` ``delta`` (the ``support_anisotropy``
    coefficient: ``k_y = k + delta``, ``k_x = k - delta``), ``cross_coupling`` ``q``
    (``cross_coupled_stiffness``) and ``ip`` in [0, 1).  The eigen-analysis is the
    synchronous model's (:func:`rotor_env.diagnosis.synchronous.whirl_branches`, on these
    effects): the eigenvalues ``lambda = -sigma +- i w`` of its 4x4 real state matrix give
    the damped frequencies ``w``; each mode's eigenvector ``(v_y, v_x)`` whirls forward when
    its forward part ``|v_y + i v_x|`` exceeds its backward part ``|v_y - i v_x|`` (a
    straight-line mode has both equal).  Returns ``{"forward": w_f, "backward": w_b}``,
    signed (``w_b < 0`` for a backward whirl; rad per time unit of the inputs), NaN where a
    mode is over-critically damped.  Where both modes whirl the same way (strong
    anisotropy), the higher one is the ``forward`` branch, each keeping the sign of its own
    whirl.

    Covered: isotropic and anisotropic supports, gyroscopic stiffening/softening,
    viscous damping and cross-coupled stiffness (all fixed-frame, linear, constant
    coefficients at each speed).  Not covered: rotating-frame asymmetry (a crack:
    periodic coefficients, which need Floquet analysis), non-linear stiffness and dry
    friction.
    """
    model = SynchronousModel(_whirl_model_effects(), ip=float(ip))
    # ``others``: the coefficients of further declared whirl effects (absent ones are 0)
    given = {"stiffness": stiffness, "viscous_damping": damping, "support_anisotropy": anisotropy,
             "cross_coupled_stiffness": cross_coupling, **(others or {})}
    coef = model.coef_vector({e: np.atleast_1d(np.asarray(given[e], dtype=float)) for e in model.layout
                              if e in given})
    return whirl_branches(model, coef, speed)


def whirl_peaks(
    t: np.ndarray, signal: np.ndarray, phi: np.ndarray, *, revolutions: int = 8, max_order: float = 4.0,
    min_ratio: float = 20.0, clearance: float = 0.3,
) -> tuple[np.ndarray, np.ndarray]:
    """Non-synchronous whirl peaks in the data: ``(speeds, signed frequencies)`` (rad per
    time unit), one per block of the waterfall at most.

    In each block (:func:`~rotor_env.diagnosis.orders.order_map` of the complex
    ``signal``) the largest line farther than ``clearance`` orders from every integer
    order (the forced 0x, 1x, 2x ... response and their window leakage) is kept if it
    stands ``min_ratio`` times above the block's median: a free whirl (the transient
    after a critical, an instability) at frequency ``order * speed``.
    """
    t, phi = np.asarray(t, dtype=float), np.asarray(phi, dtype=float)
    omega = np.abs(np.gradient(phi, t))
    speeds, orders, amp = order_map(t, phi, omega, np.asarray(signal), revolutions=revolutions,
                                    max_order=max_order)
    free = np.abs(orders - np.round(orders)) > clearance
    out_s, out_w = [], []
    if amp.size and free.any():
        for s, row in zip(speeds, amp, strict=True):
            j = int(np.argmax(np.where(free, row, -np.inf)))
            if row[j] > min_ratio * max(float(np.median(row)), 1e-300):
                out_s.append(s)
                out_w.append(orders[j] * s)
    return np.array(out_s), np.array(out_w)


# ------------------------------------------------------------------ parameter tracks
@dataclass
class ParameterTracks:
    """The recursive identifier's estimates over time.

    ``coefficients[name][k]``: each regression coefficient after sample ``k``;
    ``log10_p[effect][k]`` and ``significant[effect][k]``: its effect-last F test at the
    latest checkpoint at or before ``k`` (False/0 before the first); ``groups``: effect ->
    its coefficients.
    """

    t: np.ndarray
    coefficients: dict[str, np.ndarray]
    significant: dict[str, np.ndarray]
    log10_p: dict[str, np.ndarray]
    groups: dict[str, tuple[str, ...]] = field(default_factory=dict)
    forgetting: float = 1.0


def parameter_tracks(
    meas,
    model: Sequence[str],
    ip: float,
    forgetting: float = 0.9995,
    *,
    alpha: float = 0.05,
    equation: str = "both",
    known: Mapping[str, Mapping[str, float]] | None = None,
    checkpoints: int = 200,
) -> ParameterTracks:
    """Run the recursive QR identifier (:class:`identifier.RecursiveQR`) over ``meas``.

    The regression is the diagnosis's (:func:`rotor_env.regression.regression_arrays`:
    both equations per sample, the stiffness known ``k = 1`` unless ``stiffness`` is in
    ``model``).  ``forgetting`` ``lambda`` per regression row: the memory is about
    ``1 / (1 - lambda)`` rows (``/2`` samples with both equations), so a coefficient that
    changes (a crack opening) is followed.  The coefficients are recorded after every
    sample (inside the compiled update); each effect's effect-last partial F test (Kish
    effective samples under forgetting) at ``checkpoints`` evenly spaced samples, held to
    the next.  Those p-values assume a white residual: on coloured residuals they are
    optimistic (the diagnosis's verdicts use HAC tests instead).
    """
    from identifier import RecursiveQR

    from ..regression import RegressionSpec, regression_arrays

    spec = RegressionSpec(effects=tuple(model), equation=equation, known=known or {})
    data = np.ascontiguousarray(meas.data)
    X, y = regression_arrays(spec, data, float(ip))
    rows, n, m = spec.rows_per_sample, spec.n_columns, len(data)
    est = RecursiveQR(columns=spec.columns, groups=spec.groups, forgetting=forgetting)
    coef = np.zeros((m, n))
    names = tuple(spec.groups)
    at, tests_lp, tests_sig = [], [], []
    edges = np.unique(np.linspace(0, m, max(1, checkpoints) + 1).round().astype(int))
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        h = est.update_many(X[a * rows:b * rows], y[a * rows:b * rows], return_coefficients=n)
        coef[a:b] = h.coefficients[n][rows - 1::rows]
        tests = est.effect_tests(alpha)
        at.append(b - 1)
        tests_lp.append(tests.log10_p)
        tests_sig.append(tests.significant())
    latest = np.searchsorted(np.asarray(at), np.arange(m), side="right") - 1  # causal: hold the last test
    lp = np.where(latest[:, None] >= 0, np.asarray(tests_lp)[np.maximum(latest, 0)], 0.0)
    sig = np.where(latest[:, None] >= 0, np.asarray(tests_sig)[np.maximum(latest, 0)], False)
    return ParameterTracks(
        t=np.asarray(meas.t, dtype=float).copy(),
        coefficients={c: coef[:, j] for j, c in enumerate(spec.columns)},
        significant={e: sig[:, g].astype(bool) for g, e in enumerate(names)},
        log10_p={e: lp[:, g] for g, e in enumerate(names)},
        groups=dict(spec.groups),
        forgetting=float(forgetting),
    )


def monitor_alarms(meas, effects: Sequence[str], ip: float, *, arl0: float = 1e7) -> list[dict]:
    """The alarms of the on-line monitor's calibrated test over ``meas`` (dimensionless).

    :class:`rotor_env.monitor.Monitor` (block evidence with HAC variance and an in-control
    calibration, one CUSUM per effect, threshold from the target ARL0 ``arl0`` samples:
    :mod:`rotor_env.monitor.detector`) run over the record: each alarm is
    ``{"event", "effect", "t_onset", "t_alarm"}``.  These are the marks a parameter-track
    figure shows; the identifier's own effect-last F tests assume a white residual and
    flag effects long before they exist on real, coloured residuals.
    """
    from ..monitor.core import Monitor, MonitorConfig

    data = np.ascontiguousarray(meas.data)
    mon = Monitor(MonitorConfig(effects=tuple(effects), ip=float(ip), arl0=arl0))
    events = [e for e in mon.update(data) if e.get("event") in ("appeared", "changed", "disappeared")]
    return [{k: e[k] for k in ("event", "effect", "t_onset", "t_alarm")} for e in events]
