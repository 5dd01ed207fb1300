"""Simulated streams with a known truth, for the monitor's tests and benchmark.

A crack that *appears* is the simulator's :class:`~rotor_env.params.Crack` (``D`` jumps
at ``t_c``).  A crack that *grows* is ``D(t) = rate (t - t_c)`` after ``t_c``: on a
run-up of constant acceleration ``a`` from rest the time is ``phid / a``, so a
test-only effect with the asymmetry's columns times ``max(phid - a t_c, 0) / a``
(registered only while it is simulated) is exactly that crack.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..effects import EFFECTS, PHYSICAL_EFFECTS, Effect, Parameter, register_effect
from ..measurements import Measurements
from ..params import Crack, RotorParams
from ..simulator import Simulator

__all__ = ["HEALTHY_ROTORS", "growing_crack", "healthy", "with_crack"]

#: healthy parameter sets (no asymmetry, no quadratic stiffness): ip, tau, beta, c, h
HEALTHY_ROTORS: dict[str, dict[str, float]] = {
    "table1": {"ip": 0.3, "tau": 0.02, "beta": 0.0, "c": 0.03, "h": 0.01},
    "light": {"ip": 0.2, "tau": 0.01, "beta": 0.5, "c": 0.02, "h": 0.0},
    "heavy": {"ip": 0.4, "tau": 0.03, "beta": 2.0, "c": 0.05, "h": 0.0},
}


def _params(rotor: dict[str, float], crack: Crack | None = None, D: float = 0.0, effects=PHYSICAL_EFFECTS,
            **extra: float) -> RotorParams:
    values = {k: v for k, v in rotor.items() if k != "ip"}
    values.update({"D": D, "k30": 0.0, "k21": 0.0, "k12": 0.0, "k03": 0.0, **extra})
    return RotorParams(ip=rotor["ip"], values=values, effects=effects, crack=crack)


def healthy(rotor: str = "table1", *, t_end: float = 300.0, dt: float = 0.02) -> Measurements:
    """A noise-free run-up (0.01) of a healthy rotor; add noise per seed with ``with_noise``."""
    return Simulator(_params(HEALTHY_ROTORS[rotor])).run(t_end=t_end, dt=dt, run_up=0.01)


def with_crack(D_before: float, D_after: float, t_c: float = 250.0, *, rotor: str = "table1",
               t_end: float = 300.0, dt: float = 0.02) -> Measurements:
    """A run-up whose asymmetry jumps from ``D_before`` to ``D_after`` at ``t_c`` (noise-free)."""
    params = _params(HEALTHY_ROTORS[rotor], crack=Crack(t_c, D_after), D=D_before)
    return Simulator(params).run(t_end=t_end, dt=dt, run_up=0.01)


_RATE = 0.01


@njit(cache=True)
def _growth(phid: float) -> float:
    return max(phid - 2.5, 0.0) / _RATE  # t - 250 on the 0.01 run-up


def _growing_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    g = np.maximum(phid - 2.5, 0.0) / 0.01
    c2, s2 = np.cos(2.0 * phi), np.sin(2.0 * phi)
    return (-g * (th_y * c2 + th_x * s2),), (-g * (th_y * s2 - th_x * c2),)


_GROWING = Effect(
    name="test_growing_crack", parameters=(Parameter("D_rate", 0.0, "asymmetry growth per time unit"),),
    coefficients=("D_rate",), columns=_growing_columns, to_coefficients=lambda p: (p["D_rate"],),
    from_coefficients=lambda c: {"D_rate": float(c[0])}, moment="-D_rate (t - 250) e^{2i phi} conj(z)",
    cause="a crack growing from t = 250 (test only)", signature="as asymmetry, growing",
)


def growing_crack(rate: float, *, rotor: str = "table1", t_end: float = 300.0, dt: float = 0.02) -> Measurements:
    """``D = rate (t - 250)`` after ``t = 250`` on the 0.01 run-up (noise-free)."""
    added = _GROWING.name not in EFFECTS
    if added:
        register_effect(_GROWING)
    try:
        params = _params(HEALTHY_ROTORS[rotor], effects=(*PHYSICAL_EFFECTS, _GROWING.name), D_rate=rate)
        return Simulator(params).run(t_end=t_end, dt=dt, run_up=_RATE)
    finally:
        if added:
            EFFECTS.pop(_GROWING.name, None)


def delay(events: list[dict], effect: str, t_c: float) -> float:
    """Time from ``t_c`` to the first alarm on ``effect`` at or after it (``inf``: none)."""
    hits = [e["t_alarm"] for e in events if e["effect"] == effect and e["t_alarm"] >= t_c]
    return min(hits) - t_c if hits else math.inf


def _unbalance_step_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    # 0 before t = 250 on the 0.01 run-up, 1 from 1e-4 after (scalars and arrays alike)
    on = np.minimum(np.maximum((phid - 2.5) * 1e6, 0.0), 1.0)
    s, c = np.sin(phi), np.cos(phi)
    a = on * (1.0 - ip) * (phidd * c - phid * phid * s)
    b = on * (1.0 - ip) * (phidd * s + phid * phid * c)
    return (a, -b), (b, a)


_UNBALANCE_STEP = Effect(
    name="test_unbalance_step",
    parameters=(Parameter("dtau_cos", 0.0, "unbalance added at t = 250, in phase"),
                Parameter("dtau_sin", 0.0, "unbalance added at t = 250, in quadrature")),
    coefficients=("dtau_cos", "dtau_sin"), columns=_unbalance_step_columns,
    to_coefficients=lambda p: (p["dtau_cos"], p["dtau_sin"]),
    from_coefficients=lambda c: {"dtau_cos": float(c[0]), "dtau_sin": float(c[1])},
    moment="as unbalance, from t = 250", cause="a balance weight lost at t = 250 (test only)",
    signature="1X, from t = 250",
)


def unbalance_step(dtau: float, angle: float = 0.0, *, rotor: str = "table1", t_end: float = 300.0,
                   dt: float = 0.02) -> Measurements:
    """The healthy run-up whose unbalance gains ``dtau`` at ``angle`` (rad) at ``t = 250``
    (a balance weight thrown off; noise-free)."""
    added = _UNBALANCE_STEP.name not in EFFECTS
    if added:
        register_effect(_UNBALANCE_STEP)
    try:
        params = _params(HEALTHY_ROTORS[rotor], effects=(*PHYSICAL_EFFECTS, _UNBALANCE_STEP.name),
                         dtau_cos=dtau * math.cos(angle), dtau_sin=dtau * math.sin(angle))
        return Simulator(params).run(t_end=t_end, dt=dt, run_up=_RATE)
    finally:
        if added:
            EFFECTS.pop(_UNBALANCE_STEP.name, None)
