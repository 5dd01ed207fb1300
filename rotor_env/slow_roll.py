"""Slow-roll compensation: the probe's runout read at slow roll and subtracted.

A probe track that is out of round, or marked (electrical runout), adds a pattern fixed
to the shaft angle to the measured inclinations: ``z_meas = z + r e^{i(phi + gamma)}``
(``z = theta_y + i theta_x``).  In the equations of motion it is a constant 1x forcing
plus an unbalance-shaped term, so one probe plane cannot tell it from a shaft bow
(docs/PHYSICS.md, ``shaft_bow``'s caveat), and left in the data it biases the unbalance.
Field practice removes it with the **slow-roll vector**: the 1x reading at speeds where
the rotor barely responds dynamically.

Here the slow-roll vector is fitted, not just averaged: in the band ``|speed| <=
speed_max`` the angles are regressed on ``e^{i phi}`` (the runout, constant),
``speed^2 e^{i phi}`` and ``speed^4 e^{i phi}`` (the unbalance response below the
critical, ``~ speed^2 / (1 - a speed^2)``, to second order) and a constant (a static
offset), so the runout is the response *extrapolated to zero speed* and the unbalance's
share of the band does not leak into it.  The pattern is subtracted
from the angles, and its rates ``i phi' r e^{i phi}`` and accelerations ``(i phi'' -
phi'^2) r e^{i phi}`` from theirs, so the record stays consistent.

A bow shows at slow roll too (its static deflection): compensated, it turns into an
unbalance-shaped forcing — the standard consequence of slow-roll compensation; use it
when the 1x at slow roll is known to be runout.
"""

from __future__ import annotations

import math

import numpy as np

from .measurements import Measurements

__all__ = ["compensate_slow_roll", "slow_roll_vector"]

#: fewest samples and revolutions in the slow-roll band
MIN_SAMPLES = 50
MIN_REVOLUTIONS = 2.0


def slow_roll_vector(meas: Measurements, speed_max: float) -> complex:
    """The runout ``r e^{i gamma}`` (complex, ``theta_y + i theta_x`` convention) from the
    samples with ``|speed| <= speed_max``, extrapolated to zero speed."""
    if not (math.isfinite(speed_max) and speed_max > 0):
        raise ValueError(f"slow-roll speed must be a positive number, got {speed_max!r}")
    sel = np.abs(meas.phi_dot) <= speed_max
    turns = float(np.ptp(meas.phi[sel])) / (2 * math.pi) if sel.any() else 0.0
    if sel.sum() < MIN_SAMPLES or turns < MIN_REVOLUTIONS:
        raise ValueError(f"slow roll below speed {speed_max:g}: {int(sel.sum())} samples, {turns:.2g} revolutions "
                         f"(at least {MIN_SAMPLES} samples and {MIN_REVOLUTIONS:g} revolutions are needed)")
    phi, w = meas.phi[sel], meas.phi_dot[sel]
    e = np.exp(1j * phi)
    w2 = w * w
    A = np.column_stack([e, w2 * e, w2 * w2 * e, np.ones_like(e)])
    z = meas.theta_y[sel] + 1j * meas.theta_x[sel]
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    return complex(coef[0])


def compensate_slow_roll(meas: Measurements, speed_max: float) -> tuple[Measurements, complex]:
    """The record with the slow-roll vector's pattern removed, and that vector."""
    r = slow_roll_vector(meas, speed_max)
    e = r * np.exp(1j * meas.phi)
    w, a = meas.phi_dot, meas.phi_ddot
    d = meas.data.copy()
    cols = {"z": (5, 4), "zd": (7, 6), "zdd": (9, 8)}  # (theta_y, theta_x) columns
    for key, pattern in (("z", e), ("zd", 1j * w * e), ("zdd", (1j * a - w * w) * e)):
        cy, cx = cols[key]
        d[:, cy] -= pattern.real
        d[:, cx] -= pattern.imag
    return Measurements(d, meas.source, meas.estimated), r
