"""A second mode of the rotor in the waveforms' model: another oscillator the probes see.

Why
---
A rotor from a finite-element code, or a rig with two disks, has more modes than the one the
library's effects act on.  Where a second mode lies in the run, or just above it, the probes
read its response beside the first mode's: a one-mode model misses such a record by many
times its floor (a two-disk rotor whose second critical lies 2.3 times above the first, 30 %
above the top speed: 3.8x, nothing named, its unbalance read half its size and 150 deg off),
and a fault's fit then takes what it can of the other mode (an open crack of the same rotor
was read as a hinge crack with ``dk`` 0.49).  Taking the 1X vectors' fit of the other mode
away leaves its free ring at its own frequency in the waveforms, which no 1X vector holds.

The model
---------
The probes read the first mode's orbit (the rotor model with its effects) plus the second
mode's, both in ``z = th_y + i th_x`` (forward whirl ``e^{+i phi}``):

    z2'' + c2 z2' + k2 z2 = u2 (W^2 - i W') e^{i phi}

an isotropic, non-gyroscopic oscillator in the first mode's time unit (natural frequency
``sqrt(k2)``, damping ratio ``c2 / (2 sqrt(k2))``), forced by the shaft's unbalance through
its own modal unbalance ``u2`` (complex: the unbalance's share in that mode and the mode's
shape at the probes' plane together; ``W^2 - i W'`` is the d'Alembert force of a mass
eccentricity on a spinning-up shaft).  Like the first mode, its state is free at the start of
every shooting segment: four more nuisance parameters per segment, projected out with the
first mode's start state (variable projection), so the fit is stable through the second
critical as it is through the first.  Its parameters: ``k2`` and ``c2`` (non-linear) and the
real and imaginary parts of ``u2`` (linear).

Sensitivities, without differences of whole runs: ``z2`` is linear in ``u2`` and in its start
state, so those columns are the unit-forced response ``w`` (``w = w' = 0`` at the segment's
start) and the free responses ``g1``, ``g2`` from ``(1, 0)`` and ``(0, 1)`` (each times ``1``
and ``i``); ``d z2 / d k2`` and ``d z2 / d c2`` obey the same oscillator forced by ``-z2``
and ``-z2'`` from rest.  All are integrated together by the RK4 steps of the first mode's
kernel (the spin between samples at constant acceleration).

What it does not hold: faults acting on the second mode (the library's effects act on the
first), a gyroscopic split of the second mode's forward and backward whirl, its own support
anisotropy, and a mode below the run (above its critical a mode's 1X tends to ``-u2``, a
constant the probes' runout term already holds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from .spin import spin_between

__all__ = ["MODE_PARAMETERS", "N_MODE_PARAMETERS", "N_MODE_STATES", "SecondMode", "shoot_second_mode"]

#: the second mode's parameters, in the fit's layout: stiffness and damping (first mode's
#: time unit), the modal unbalance's real and imaginary part
MODE_PARAMETERS = ("k", "c", "u_cos", "u_sin")
N_MODE_PARAMETERS = len(MODE_PARAMETERS)
#: its start state in each segment: ``Re z2, Im z2, Re z2', Im z2'``
N_MODE_STATES = 4
#: RK4 steps are kept below this many radians of the second mode's free whirl: its relative
#: phase error over a segment of ``T`` time units, ``w T (w h)^4 / 120``, is then 1.3e-4 at
#: ``w = 2.5``, ``T = 12`` (a mode 100x the noise is predicted to 0.013 of it)
MAX_STEP_RADIANS = 0.15


@dataclass(frozen=True)
class SecondMode:
    """A second mode's parameters in the first mode's time unit: stiffness ``k`` (natural
    frequency ``sqrt(k)`` times the first mode's time scale), damping ``c`` and the modal
    unbalance ``u`` (the grid's displacement unit)."""

    k: float
    c: float
    u: complex = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.k) and self.k > 0):
            raise ValueError(f"a second mode's stiffness must be a positive number, got {self.k!r}")
        if not (math.isfinite(self.c) and self.c >= 0):
            raise ValueError(f"a second mode's damping must be a non-negative number, got {self.c!r}")

    @classmethod
    def from_frequency(cls, frequency: float, damping_ratio: float, u: complex = 0.0) -> SecondMode:
        """From its natural frequency (first mode's time unit) and damping ratio."""
        return cls(frequency * frequency, 2.0 * damping_ratio * frequency, u)

    @classmethod
    def from_array(cls, values: np.ndarray) -> SecondMode:
        k, c, ur, ui = (float(v) for v in values)
        return cls(k, c, complex(ur, ui))

    def as_array(self) -> np.ndarray:
        return np.array([self.k, self.c, self.u.real, self.u.imag])

    @property
    def frequency(self) -> float:
        return math.sqrt(self.k)

    @property
    def damping_ratio(self) -> float:
        return self.c / (2.0 * math.sqrt(self.k))

    def steady_states(self, phi: np.ndarray, phid: np.ndarray) -> np.ndarray:
        """``(n, 4)``: the steady 1X response's state at the given angles and speeds (a
        segment's first guess): ``z2 = u W^2 e^{i phi} / (k - W^2 + i c W)``, ``z2' = i W z2``."""
        W = np.asarray(phid, dtype=float)
        z = self.u * W * W * np.exp(1j * np.asarray(phi, dtype=float)) / (self.k - W * W + 1j * self.c * W)
        v = 1j * W * z
        return np.column_stack([z.real, z.imag, v.real, v.imag])


def substeps(mode: SecondMode, dt: float, at_least: int = 1) -> int:
    """RK4 steps per grid sample for the second mode (:data:`MAX_STEP_RADIANS`)."""
    return max(int(at_least), int(math.ceil(mode.frequency * dt / MAX_STEP_RADIANS)))


@njit(cache=True)
def _deriv(F, u, k, c, y, f):
    # y: w, w', g1, g1', g2, g2', z, z', sk, sk', sc, sc' (complex)
    f[0] = y[1]
    f[1] = F - c * y[1] - k * y[0]
    f[2] = y[3]
    f[3] = -c * y[3] - k * y[2]
    f[4] = y[5]
    f[5] = -c * y[5] - k * y[4]
    f[6] = y[7]
    f[7] = u * F - c * y[7] - k * y[6]
    f[8] = y[9]
    f[9] = -y[6] - c * y[9] - k * y[8]
    f[10] = y[11]
    f[11] = -y[7] - c * y[11] - k * y[10]


@njit(cache=True)
def _force(p, w, a):
    return (w * w - 1j * a) * (math.cos(p) + 1j * math.sin(p))


@njit(cache=True)
def _write(y, u, k_out, pred, jac, col0):
    # (th_x, th_y) = (Im, Re) of each complex column: k, c, Re u, Im u (i w), Re z0, Im z0,
    # Re v0, Im v0 (i g)
    cols = (y[8], y[10], y[0], 1j * y[0], y[2], 1j * y[2], y[4], 1j * y[4])
    for j in range(8):
        jac[k_out, 0, col0 + j] = cols[j].imag
        jac[k_out, 1, col0 + j] = cols[j].real
    pred[k_out, 0] = y[6].imag
    pred[k_out, 1] = y[6].real


@njit(cache=True)
def _shoot_range(s0, s1, t, phi, phid, seg, states, k, c, u, nsub, pred, jac, col0):
    y = np.zeros(12, dtype=np.complex128)
    ys = np.zeros(12, dtype=np.complex128)
    f1 = np.zeros(12, dtype=np.complex128)
    f2 = np.zeros(12, dtype=np.complex128)
    f3 = np.zeros(12, dtype=np.complex128)
    f4 = np.zeros(12, dtype=np.complex128)
    for s in range(s0, s1):
        i0 = seg[s, 0]
        i1 = seg[s, 1]
        y[:] = 0.0
        y[2] = 1.0
        y[5] = 1.0
        y[6] = states[s, 0] + 1j * states[s, 1]
        y[7] = states[s, 2] + 1j * states[s, 3]
        _write(y, u, i0, pred, jac, col0)
        for i in range(i0, i1):
            dts = t[i + 1] - t[i]
            a = (phid[i + 1] - phid[i]) / dts
            h = dts / nsub
            for m in range(nsub):
                p0, w0 = spin_between(phi[i], phid[i], a, m * h)
                pm, wm = spin_between(p0, w0, a, 0.5 * h)
                pe, we = spin_between(p0, w0, a, h)
                hh = 0.5 * h
                F0 = _force(p0, w0, a)
                Fm = _force(pm, wm, a)
                Fe = _force(pe, we, a)
                _deriv(F0, u, k, c, y, f1)
                for q in range(12):
                    ys[q] = y[q] + hh * f1[q]
                _deriv(Fm, u, k, c, ys, f2)
                for q in range(12):
                    ys[q] = y[q] + hh * f2[q]
                _deriv(Fm, u, k, c, ys, f3)
                for q in range(12):
                    ys[q] = y[q] + h * f3[q]
                _deriv(Fe, u, k, c, ys, f4)
                for q in range(12):
                    y[q] += h / 6.0 * (f1[q] + 2.0 * f2[q] + 2.0 * f3[q] + f4[q])
            _write(y, u, i + 1, pred, jac, col0)


@njit(cache=True, parallel=True)
def _shoot(t, phi, phid, seg, states, k, c, u, nsub, pred, jac, col0):
    nseg = seg.shape[0]
    nchunk = min(nseg, 16)
    for ch in prange(nchunk):
        _shoot_range(ch * nseg // nchunk, (ch + 1) * nseg // nchunk, t, phi, phid, seg, states, k, c, u, nsub,
                     pred, jac, col0)


def shoot_second_mode(t: np.ndarray, phi: np.ndarray, phid: np.ndarray, segments: np.ndarray, states: np.ndarray,
                      mode: np.ndarray, nsub: int, pred: np.ndarray, jac: np.ndarray, col0: int) -> None:
    """The second mode's response added to nothing: writes ``pred`` ``(N, 2)`` (``th_x, th_y``)
    and ``jac[:, :, col0:col0 + 8]`` (its parameters :data:`MODE_PARAMETERS`, then its start
    state) at the samples of every segment, from the segments' start ``states`` ``(S, 4)`` and
    ``mode`` ``(k, c, Re u, Im u)``."""
    k, c, ur, ui = (float(v) for v in mode)
    _shoot(np.ascontiguousarray(t), np.ascontiguousarray(phi), np.ascontiguousarray(phid),
           np.ascontiguousarray(segments), np.ascontiguousarray(states, dtype=float), k, c, complex(ur, ui),
           int(nsub), pred, jac, int(col0))
