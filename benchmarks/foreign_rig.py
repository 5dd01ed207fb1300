"""A foreign rig simulator: records from equations written apart from the package, diagnosed.

Why
---
``benchmarks/rig_suite.py`` makes its records with the package's own simulator
(``rotor_env.rig_simulation``), so the diagnosis's model is exact there.  A customer's records
come from a real rig, or from somebody else's simulator.  This file is such a simulator,
written from the rotordynamics literature in SI units, without importing the package's
simulator, effects, parameters or rig simulation (only the file readers and ``diagnose_rig``,
the product under test, are imported, and only by the runner).

The rotor (Laval / Jeffcott)
----------------------------
A disk of mass ``m`` [kg] on a massless shaft of stiffness ``k`` [N/m] with viscous damping
``c`` [N s/m]; the disk centre moves in a fixed plane, ``x`` along the probes' reference
direction (top dead centre), ``y`` 90 degrees on in the direction of rotation (the shaft turns
counter-clockwise from ``x`` to ``y``).  ``k = m wn^2``, ``c = 2 zeta m wn`` with natural
frequency ``fn`` 20-50 Hz, ``zeta`` 1-4 %, ``m`` 1-20 kg.  Equation of motion:

    m x'' + c x' = F_x,      m y'' + c y' = F_y

where ``F`` is the sum of the shaft's elastic force and of every force below (each written as
forces in newtons; the shaft's elastic force is written in the shaft's own body frame).

Spin.  A constant-acceleration run-up or coast-down between 0.3 and 1.8 times the critical
(``fn``) in 8-11 s (drawn):  ``phi(t) = phi0 + W0 t + alpha t^2 / 2``,  ``W = W0 + alpha t``;
with ``--profile updown`` the run-up (or coast-down) followed by a dwell and the way back in one
record; with ``--profile motor`` the same end speeds reached as a motor drives a rotor, fast at first
and slowly at the end (``W = W0 + K (1 - exp(-2 t / duration))``, :func:`spin`).
Before ``t = 0`` the rotor turns at ``W0`` for ``min(5 / (zeta wn), 8 s)`` (started at the
isotropic rotor's steady state) so that the record starts settled.  ``phi`` is the angle of a
body-fixed mark; the keyphasor notch sits at a random body angle ``nu`` (drawn), and every
fault's orientation is drawn as an angle *from the notch, in the direction of rotation*
(``psi``): its body angle is ``nu + psi`` and its direction in the fixed frame is
``theta = phi + nu + psi``.  The keyphasor probe looks along the probes' reference direction
(``x``), so the pulse's leading edge is where ``phi + nu = 0 (mod 2 pi)``.

Unbalance (always).  Mass eccentricity ``e`` at body angle ``beta``; the d'Alembert force of
the eccentric mass:

    F_x = m e (W^2 cos(phi+beta) + alpha sin(phi+beta))
    F_y = m e (W^2 sin(phi+beta) - alpha cos(phi+beta))

``e = 2 zeta P`` for a drawn steady peak ``P`` of 50-150 um (so ``e`` is 1-12 um; the sweep's
transient peak is a little lower).

Shaft (healthy): ``F = -k (x, y)``.  With a fault the elastic force is computed in the shaft's
body axes ``(xi, eta)`` (``xi`` at the fixed-frame angle ``theta``):
``xi = x cos theta + y sin theta``, ``eta = -x sin theta + y cos theta``, ``f_xi = -k_xi xi``,
``f_eta = -k_eta eta``, rotated back.

Faults (one per record; sizes and angles drawn from the seed):

* ``healthy``: unbalance and damping only.
* ``asymmetry`` (an open crack, a keyway, a flat): ``k_xi = k (1 + D)``, ``k_eta = k (1 - D)``,
  ``D`` 0.02-0.04, the stiff axis ``xi`` at ``psi`` 0-180 deg from the notch.  Reported: ``D``
  and ``psi``.
* ``breathing_crack`` (horizontal rotor, gravity): the crack's weak axis ``xi`` (the normal of
  its faces, its mouth) at ``psi`` 0-360 deg from the notch; ``k_eta = k``,
  ``k_xi = k - dk f``, ``dk / k`` 0.02-0.06.  Breathing (Mayes & Davies 1984): the crack is
  fully open when its mouth faces the static load (the shaft's sagging side is in tension),
  ``f = (1 + cos(theta - gamma)) / 2`` with ``gamma`` the load's direction; or, with
  ``--crack-law gasch``, Gasch's hinge switched by the deflection itself,
  ``f = (1 + tanh(xi / 1 um)) / 2`` (open while the deflection along the mouth is positive).
  The load is the disk's weight ``m g`` along ``-x`` (``x`` is up): a static sag
  ``g / wn^2`` of 100-620 um -- larger than the package's side loads (4-8 % of the peak).
* ``breathing_crack_side`` (vertical rotor): the same crack under a constant side load
  ``k d`` (a magnet, a bearing preload) with a static deflection ``d`` of 15-40 um in a random
  fixed direction, ``dk / k`` 0.05-0.1.
* ``rub``: radial contact of stiffness ``k_r`` (0.5-2 k) beyond a clearance ``delta``
  (0.45-0.75 of the healthy record's peak: touched around the critical), Coulomb friction
  ``mu`` (0.1-0.3) against the sliding speed of the shaft's surface (radius ``R`` = 50 mm):
  with ``r = |(x, y)| > delta``, ``n = (x, y) / r``, ``t`` the unit vector 90 deg on,
  ``N = k_r (r - delta)``, ``v_s = W R + t . (x', y')``,
  ``F = -N n - mu N tanh(v_s / 1 mm/s) t``.
* ``shaft_bow``: the shaft's unloaded elastic line passes the disk at ``b`` (5-15 um) at body
  angle ``psi``: ``F = -k ((x, y) - b (cos, sin)(phi + nu + psi))``.
* ``support_anisotropy``: the supports make the total stiffness ``k (1 + s)`` along a fixed
  axis at ``chi`` (0-180 deg from ``x``) and ``k (1 - s)`` across it, ``s`` 0.04-0.08.
* ``cross_coupled_stiffness``: ``F_x = -q y``, ``F_y = +q x`` (``k_xy = q``, ``k_yx = -q``),
  ``q`` 0.3-0.6 of ``c wn`` (stable).
* ``runout``: a healthy rotor whose probe tracks are not true: each probe adds
  ``R_p cos(a_p - phi - nu - psi_p)`` (its own track pattern, ``R_p`` 3-8 um) to its reading
  only.
* ``gravity``: a healthy horizontal rotor under its weight ``m g`` (the static sag alone; a
  linear rotor's sag is a constant the probes' DC removal takes away).
* ``two_modes`` (what a finite-element code's rotor has): a second disk of mass ``mu m``
  (``mu`` 0.5-1.5) on the same shaft, the probes at the first.  The shaft holds each disk to
  the bearings with a stiffness in proportion to its mass (``k``, ``mu k``) and couples them
  with ``kc``; the damping is in proportion to the masses.  The first mode (the disks
  together) is at ``fn``, the second (against each other) at ``r fn`` with ``r`` 1.3-2.5:
  ``kc = (m (r wn)^2 - k) / (1 + 1/mu)``.  The second disk has its own unbalance (0.5-2 times
  the first's, at its own angle).  The run still goes 0.3-1.8 ``fn``, so the second critical
  is inside the run (``r`` < 1.8) or above it, where its response still grows with speed.
  Expected: no fault (the 1X vectors' ``second_mode`` is tolerated).
* ``two_modes_crack``: the same rotor with an open crack (``asymmetry``, ``D`` 0.03-0.06) in
  the first disk's stretch of shaft, its stiff axis at ``psi``.  The first mode sees
  ``D / (1 + mu)`` of it (its modal stiffness is ``k (1 + mu)``), the second ``D / ((1 + 1/mu)
  r^2)`` (shape ``[1, -1/mu]``, modal stiffness ``(1 + 1/mu) r^2 k``): the size compared is
  that of the mode the diagnosis holds as its own (its natural frequency nearer to it).

Recording, like a data acquisition system: sample rate 2.5, 5, 10 or 20 kHz (drawn, or
``--fs``); the keyphasor an ideal square notch sampled at that rate (5 V, 0 V in the notch, the
notch 4 % of a turn, its leading edge at the notch angle: no ramp); two proximity probes at
+45 and -45 deg from ``x`` (the rig file's ``{"x": 45, "y": -45}``: angles in the direction of
rotation), each reading the disk's displacement towards itself, ``x cos a + y sin a``, in um,
plus a DC gap (900-1400 um), plus Gaussian white noise of the given std (``--noise``), plus
optionally first-order coloured noise (``--colour RHO``: an AR(1) part of the same std), and
optionally every channel through the same analog anti-alias filter (``--anti-alias``: a 4-pole
Butterworth at ``fs / 2.56``, :func:`filter_channel`).  The
file is Parquet (pyarrow) with columns ``t`` (s), ``kp`` (V), ``x``, ``y`` (um); the rig file
``{"keyphasor": "kp", "probes": {"x": 45, "y": -45}, "units": {"displacement": "um"}}``.
Integrated by ``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-9, atol 1e-13 m / 1e-11 m/s) with
``t_eval`` at the sample times.

How it differs from the package's own models (the point of it)
--------------------------------------------------------------
* Dimensional equations with their own parameters; the package's time unit (its identified
  natural frequency) and length unit (mm) are not used.
* The unbalance is a mass eccentricity (the Jeffcott d'Alembert force, the acceleration term
  in quadrature), not the package's tilted principal axis.
* The crack is written as body-frame stiffnesses, its breathing by the load's direction
  (Mayes) or by the deflection (Gasch's hinge, not a cosine at all); under gravity its static
  deflection is the real sag ``g / wn^2``, up to 600 um.
* The rub's friction opposes the surface's sliding speed (spin times radius plus the whirl's
  tangential speed), smoothed over 1 mm/s; the package's uses ``sign(speed)``.
* The support anisotropy and the cross-coupling are fixed-frame stiffness matrices.
* The keyphasor's edge is an ideal step (the package's simulator ramps it over 1/100 turn):
  the pulse times carry the sampling's +-dt/2 jitter, as a real DAQ's square pulse does.
* Runout is per probe track, and the DC gap is there.
* The record starts settled at the first speed, and the spin acceleration enters the
  unbalance force.

Conventions, and what is compared
---------------------------------
Truth angles are body angles from the keyphasor notch *in the direction of rotation* (what
docs/EFFECTS.md says ``D_axis`` and ``crack_axis`` are; this benchmark found the package's
moment turning them against rotation until 2026-11-27, a crack at 50 deg then reported at
130 deg).  The unbalance's heavy spot and the supports' axis (a fixed-frame angle) are
compared in the same sense.  A crack's size: ``asymmetry`` ``D`` as is;
a ``breathing_crack`` fitted to an open crack is the same stiffness at ``D = dk / 4`` with the
stiff axis 90 deg from ``crack_axis`` (``rig_suite.crack_errors``).  For a breathing crack
``dk_crack`` is set against ``dk / k`` and ``crack_axis`` against ``psi`` (mod 180 deg; the
package's axis and breathing phase trade half turns); a ``hinge_crack`` (Gasch's law) names
which side opens: ``dk_hinge`` against ``dk / k`` and ``hinge_axis`` against ``psi`` mod 360
deg.  The floor ratio is the diagnosis's
``noise_floor`` over the probes' true noise std.

How to run
----------
    python benchmarks/foreign_rig.py                                   # every case at 0.5 and 1 um
    python benchmarks/foreign_rig.py --seed 3 --noise 0.5 --cases healthy,asymmetry,rub
    python benchmarks/foreign_rig.py --cases breathing_crack --crack-law gasch --fs 10000
    python benchmarks/foreign_rig.py --keep records/                   # keep the files written

Seeded: each case's rotor and fault come from ``(seed, case)`` and each record's noise from
``(seed, case, noise)``, so the same seed gives the same records whichever cases are run, and
the noise levels of a case are the same rotor.  One line per record on stderr; the markdown
table on stdout; ``--out`` writes every outcome as JSON.
"""

from __future__ import annotations

import os
import sys

# only where numba is not loaded yet (imported by the tests it is: a changed NUMBA_NUM_THREADS
# then makes numba refuse to compile once its thread pool runs)
if "numba" not in sys.modules:
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

import argparse
import json
import math
import tempfile
import time
import warnings
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

G = 9.80665
RIG = {"keyphasor": "kp", "probes": {"x": 45, "y": -45}, "units": {"displacement": "um"}}
PROBE_DEG = {"x": 45.0, "y": -45.0}
#: the direction the weight pulls in (fixed frame, from x = top dead centre)
DOWN = math.pi
CASES = ("healthy", "asymmetry", "breathing_crack", "breathing_crack_side", "rub", "shaft_bow",
         "support_anisotropy", "cross_coupled_stiffness", "runout", "gravity", "two_modes", "two_modes_crack")
CRACKS = ("asymmetry", "breathing_crack", "hinge_crack")
#: what the diagnosis should name for each case (any one of them); empty: nothing
EXPECTED = {"healthy": (), "asymmetry": CRACKS, "breathing_crack": CRACKS, "breathing_crack_side": CRACKS,
            "rub": ("rub",), "shaft_bow": ("shaft_bow",), "support_anisotropy": ("support_anisotropy",),
            "cross_coupled_stiffness": ("cross_coupled_stiffness",), "runout": (), "gravity": (),
            "two_modes": (), "two_modes_crack": CRACKS}
#: named without being wrong (gravity: the sag is a true static load, though unobservable; a
#: second mode is there)
TOLERATED = {"gravity": ("static_load",), "breathing_crack": ("static_load",),
             "breathing_crack_side": ("static_load",), "two_modes": ("second_mode",),
             "two_modes_crack": ("second_mode",)}
#: the cases that are a crack
CRACK_CASES = ("asymmetry", "breathing_crack", "breathing_crack_side", "two_modes_crack")
SAMPLE_RATES = (2500.0, 5000.0, 10000.0, 20000.0)
NOTCH_FRACTION = 0.04
KP_HIGH_V = 5.0
CONTACT_RADIUS_M = 0.05
RUB_SLIP_SMOOTH = 1e-3    #: m/s: the friction's sign smoothed over this sliding speed
GASCH_SMOOTH_M = 1e-6     #: m: Gasch's hinge smoothed over this deflection


# ------------------------------------------------------------------ the physics
@dataclass(frozen=True)
class Rotor:
    """A Jeffcott rotor, its run and its fault, in SI units (angles in rad)."""

    m: float                 #: disk mass, kg
    fn: float                #: natural frequency, Hz
    zeta: float              #: damping ratio
    e: float                 #: mass eccentricity, m
    beta: float              #: heavy spot's body angle
    nu: float                #: keyphasor notch's body angle
    f_from: float            #: spin frequency at t = 0, Hz
    f_to: float              #: at the end, Hz
    duration: float          #: s
    phi0: float              #: body angle phi at t = 0
    fault: str = "healthy"
    #: fault parameters (SI; angles in rad): see the module docstring
    p: dict = field(default_factory=dict)
    #: "linear" (constant acceleration) or "motor" (the speed approaches its end exponentially)
    profile: str = "linear"

    @property
    def wn(self) -> float:
        return 2 * math.pi * self.fn

    @property
    def k(self) -> float:
        return self.m * self.wn ** 2

    @property
    def c(self) -> float:
        return 2 * self.zeta * self.m * self.wn

    @property
    def W0(self) -> float:
        return 2 * math.pi * self.f_from

    @property
    def alpha(self) -> float:
        return 2 * math.pi * (self.f_to - self.f_from) / self.duration

    def phi(self, t):
        """Body angle of the mark (t < 0: the settling spin at constant speed)."""
        t = np.asarray(t, dtype=float)
        return spin(self.phi0, self.W0, self.alpha, self.duration, self.profile, t)[0]


def _spin_scalar(r: Rotor):
    """:func:`spin` at one time, in plain floats (the right-hand side's hot path)."""
    phi0, W0, A = r.phi0, r.W0, r.alpha
    if r.profile == "motor":
        T = 0.5 * r.duration
        K = A * r.duration / (1.0 - math.exp(-2.0))

        def at(t: float) -> tuple[float, float, float]:
            if t <= 0:
                return phi0 + W0 * t, W0, 0.0
            ex = math.exp(-t / T)
            return phi0 + W0 * t + K * (t - T * (1.0 - ex)), W0 + K * (1.0 - ex), K * ex / T
        return at

    if r.profile == "updown":
        def at_updown(t: float) -> tuple[float, float, float]:
            if t <= 0:
                return phi0 + W0 * t, W0, 0.0
            ph, W, a = _updown(phi0, W0, A, r.duration, t)
            return float(ph), float(W), float(a)
        return at_updown

    def at_linear(t: float) -> tuple[float, float, float]:
        if t <= 0:
            return phi0 + W0 * t, W0, 0.0
        return phi0 + W0 * t + 0.5 * A * t * t, W0 + A * t, A
    return at_linear


def _updown(phi0: float, W0: float, A: float, duration: float, tp):
    """The "updown" profile at ``tp >= 0``: from ``W0`` to ``W0 + A duration`` in the first 45 %
    of the record, held for 10 %, back to ``W0`` in the last 45 % (a test run's start-up, dwell
    and coast-down in one file)."""
    t1, t2 = 0.45 * duration, 0.55 * duration
    rate = A * duration / t1
    w1 = W0 + A * duration
    tp = np.asarray(tp, dtype=float)
    up = np.minimum(tp, t1)
    hold = np.clip(tp - t1, 0.0, t2 - t1)
    down = np.maximum(tp - t2, 0.0)
    ph = phi0 + W0 * up + 0.5 * rate * up * up + w1 * hold + w1 * down - 0.5 * rate * down * down
    W = np.where(tp <= t1, W0 + rate * tp, np.where(tp <= t2, w1, w1 - rate * down))
    a = np.where(tp < t1, rate, np.where(tp <= t2, 0.0, -rate))
    return ph, W, a


def spin(phi0: float, W0: float, A: float, duration: float, profile: str, t):
    """``(phi, W, W')`` at ``t`` (scalars or arrays; ``t < 0``: the settling spin at ``W0``).

    "linear": ``W = W0 + A t``.  "motor": ``W = W0 + K (1 - exp(-t / T))``, ``T = duration / 2``,
    ``K = A duration / (1 - exp(-2))``: the same end speed, reached fast at first and slowly at
    the end (an induction motor's run-up against its load; a coast-down against drag)."""
    tp = np.where(np.asarray(t) > 0, t, 0.0)
    neg = np.asarray(t) - tp
    if profile == "updown":
        ph, W, a = _updown(phi0, W0, A, duration, tp)
        return ph + W0 * neg, W, np.where(np.asarray(t) > 0, a, 0.0)
    if profile == "motor":
        T = 0.5 * duration
        K = A * duration / (1.0 - math.exp(-2.0))
        ex = np.exp(-tp / T)
        ph = phi0 + W0 * (tp + neg) + K * (tp - T * (1.0 - ex))
        W = W0 + K * (1.0 - ex)
        a = np.where(np.asarray(t) > 0, K * ex / T, 0.0)
        return ph, W, a
    ph = phi0 + W0 * (tp + neg) + 0.5 * A * tp * tp
    return ph, W0 + A * tp, np.where(np.asarray(t) > 0, A, 0.0)


def _rhs(r: Rotor):
    """The equations of motion ``s' = f(t, s)``, ``s = (x, y, x', y')`` (m, m/s)."""
    m, k, c, me = r.m, r.k, r.c, r.m * r.e
    beta, nu = r.beta, r.nu
    p, f = r.p, r.fault
    spin_at = _spin_scalar(r)
    cos, sin, hypot, tanh = math.cos, math.sin, math.hypot, math.tanh
    body = f in ("asymmetry", "breathing_crack", "breathing_crack_side")
    psi = p.get("psi", 0.0)
    if f == "asymmetry":
        k_stiff, k_soft = k * (1 + p["D"]), k * (1 - p["D"])
    load_x = load_y = 0.0
    if "load_N" in p:
        load_x, load_y = p["load_N"] * cos(p["load_dir"]), p["load_N"] * sin(p["load_dir"])
    dk, gamma, gasch = p.get("dk", 0.0) * k, p.get("load_dir", 0.0), p.get("law") == "gasch"
    bow = p.get("b", 0.0)
    if f == "support_anisotropy":
        ks, cchi, schi = k * p["s"], cos(p["chi"]), sin(p["chi"])
    q = p.get("q", 0.0)
    if f == "rub":
        kr, delta, mu = p["kr"], p["delta"], p["mu"]

    def rhs(t, s):
        x, y, vx, vy = s
        ph, W, a = spin_at(t)
        # unbalance: d'Alembert force of the eccentric mass
        cu, su = cos(ph + beta), sin(ph + beta)
        fx = me * (W * W * cu + a * su) - c * vx + load_x
        fy = me * (W * W * su - a * cu) - c * vy + load_y
        # the shaft
        ex, ey = x, y
        if bow:
            ex -= bow * cos(ph + nu + psi)
            ey -= bow * sin(ph + nu + psi)
        if body:
            th = ph + nu + psi
            ct, st = cos(th), sin(th)
            xi, eta = ex * ct + ey * st, -ex * st + ey * ct
            if f == "asymmetry":
                kxi, keta = k_stiff, k_soft
            else:
                br = 0.5 * (1.0 + tanh(xi / GASCH_SMOOTH_M)) if gasch else 0.5 * (1.0 + cos(th - gamma))
                kxi, keta = k - dk * br, k
            fxi, feta = -kxi * xi, -keta * eta
            fx += fxi * ct - feta * st
            fy += fxi * st + feta * ct
        else:
            fx -= k * ex
            fy -= k * ey
        if f == "support_anisotropy":
            a1, b1 = x * cchi + y * schi, -x * schi + y * cchi
            fa, fb = -ks * a1, ks * b1
            fx += fa * cchi - fb * schi
            fy += fa * schi + fb * cchi
        if q:
            fx -= q * y
            fy += q * x
        if f == "rub":
            rr = hypot(x, y)
            if rr > delta:
                nx, ny = x / rr, y / rr
                N = kr * (rr - delta)
                slip = W * CONTACT_RADIUS_M + (-ny * vx + nx * vy)
                ft = -mu * N * tanh(slip / RUB_SLIP_SMOOTH)
                fx += -N * nx - ft * ny
                fy += -N * ny + ft * nx
        return [vx, vy, fx / m, fy / m]

    return rhs


def _rhs_two_disks(r: Rotor):
    """The two-disk rotor (module docstring, ``two_modes``): ``s = (x1, y1, x1', y1', x2, y2,
    x2', y2')``; an open crack (``D``) in the first disk's stretch of shaft."""
    m, k, p = r.m, r.k, r.p
    mu, kc, D, e2, beta2 = p["mu"], p["kc"], p.get("D", 0.0), p["e2"], p["beta2"]
    m2, k2, c1 = mu * m, mu * k, r.c
    c2 = mu * c1
    beta, nu, psi = r.beta, r.nu, p.get("psi", 0.0)
    me1, me2 = m * r.e, m2 * e2
    cos, sin = math.cos, math.sin
    spin_at = _spin_scalar(r)

    def rhs(t, s):
        x1, y1, vx1, vy1, x2, y2, vx2, vy2 = s
        ph, W, a = spin_at(t)
        c_1, s_1 = cos(ph + beta), sin(ph + beta)
        c_2, s_2 = cos(ph + beta2), sin(ph + beta2)
        f1x = me1 * (W * W * c_1 + a * s_1) - c1 * vx1 - kc * (x1 - x2)
        f1y = me1 * (W * W * s_1 - a * c_1) - c1 * vy1 - kc * (y1 - y2)
        f2x = me2 * (W * W * c_2 + a * s_2) - c2 * vx2 - k2 * x2 - kc * (x2 - x1)
        f2y = me2 * (W * W * s_2 - a * c_2) - c2 * vy2 - k2 * y2 - kc * (y2 - y1)
        if D:  # the first disk's shaft in its body axes
            th = ph + nu + psi
            ct, st = cos(th), sin(th)
            xi, eta = x1 * ct + y1 * st, -x1 * st + y1 * ct
            fxi, feta = -k * (1 + D) * xi, -k * (1 - D) * eta
            f1x += fxi * ct - feta * st
            f1y += fxi * st + feta * ct
        else:
            f1x -= k * x1
            f1y -= k * y1
        return [vx1, vy1, f1x / m, f1y / m, vx2, vy2, f2x / m2, f2y / m2]

    return rhs


def _start_state(r: Rotor, t_start: float) -> list[float]:
    """The isotropic linear rotor's steady state at the first speed (plus the static sag)."""
    W = r.W0
    H = 1.0 / (r.k - r.m * W * W + 1j * r.c * W)
    z = r.m * r.e * W * W * H * np.exp(1j * (float(r.phi(t_start)) + r.beta))
    if "load_N" in r.p:
        z += r.p["load_N"] / r.k * np.exp(1j * r.p["load_dir"])
    v = 1j * W * (z - (r.p.get("load_N", 0.0) / r.k * np.exp(1j * r.p.get("load_dir", 0.0))))
    return [z.real, z.imag, v.real, v.imag]


class SimulatorUnstable(RuntimeError):
    """The drawn rotor's own motion diverged (not a product error: said apart in the table)."""


#: an orbit this many times the drawn steady peak (or the healthy record's) has left any rig
UNSTABLE_PEAK_FACTOR = 20.0


def integrate(r: Rotor, t: np.ndarray) -> np.ndarray:
    """Disk centre ``(x, y)`` in metres at the times ``t`` (>= 0), shape ``(2, len(t))``.

    Raises :class:`SimulatorUnstable` where the motion diverges: a rub's dry friction can drive
    a backward whip that grows without bound in a contact model with no stator to stop it
    (seed 11's rub reached a 25 m orbit), and an integrator that gives up is the same."""
    t_settle = min(5.0 / (r.zeta * r.wn), 8.0)
    rhs = _rhs(r)
    atol = [1e-13, 1e-13, 1e-11, 1e-11]
    start = _start_state(r, -t_settle)
    if "kc" in r.p:  # two disks: settled from rest over the same time (5 decay times of the first mode)
        rhs, atol, start = _rhs_two_disks(r), atol * 2, [0.0] * 8
    # the drawn steady peak P times the factor, beyond twice any static deflection (a sag of up to 620 um)
    limit = UNSTABLE_PEAK_FACTOR * r.e / (2 * r.zeta) + 2 * r.p.get("load_N", 0.0) / r.k

    def diverged(_t, s):
        return limit - math.hypot(s[0], s[1])

    diverged.terminal = True
    pre = solve_ivp(rhs, (-t_settle, 0.0), start, method="DOP853", rtol=1e-9, atol=atol, events=diverged)
    if pre.status == 1:
        raise SimulatorUnstable(f"the orbit passed {limit * 1e6:.0f} um ({UNSTABLE_PEAK_FACTOR:g}x the drawn peak, plus twice any sag) "
                                f"while settling, at t = {pre.t_events[0][0]:.3g} s")
    if not pre.success:
        raise SimulatorUnstable(f"settling run failed: {pre.message}")
    sol = solve_ivp(rhs, (0.0, float(t[-1])), pre.y[:, -1], method="DOP853", rtol=1e-9, atol=atol, t_eval=t,
                    events=diverged)
    if sol.status == 1:
        raise SimulatorUnstable(f"the orbit passed {limit * 1e6:.0f} um ({UNSTABLE_PEAK_FACTOR:g}x the drawn peak, plus twice any sag) "
                                f"at t = {sol.t_events[0][0]:.3g} s")
    if not sol.success:
        raise SimulatorUnstable(f"integration failed: {sol.message}")
    return sol.y[:2]


# ------------------------------------------------------------------ drawing a record
@dataclass(frozen=True)
class Record:
    """What is written: the rotor, the DAQ, the noise; and the truth to compare with."""

    case: str
    seed: int
    noise_um: float
    fs: float
    rotor: Rotor
    direction: str
    colour: float = 0.0
    gaps_um: tuple[float, float] = (0.0, 0.0)
    #: every channel through a DAQ's analog anti-alias filter (:func:`anti_alias`)
    anti_alias: bool = False
    runout: tuple[tuple[float, float], ...] = ()   #: per probe (amplitude um, angle rad from the notch)


def _case_rng(seed: int, case: str, *extra: int) -> np.random.Generator:
    return np.random.default_rng([seed, CASES.index(case), *extra])


def draw_rotor(seed: int, case: str, *, fs: float | None = None, crack_law: str = "mayes",
               psi_deg: float | None = None, profile: str = "linear") -> tuple[Rotor, dict]:
    """The case's rotor, run and fault from ``(seed, case)`` (the fault's size needing the
    healthy peak, the rub's clearance, is set by :func:`make_record`); and the DAQ draws."""
    rng = _case_rng(seed, case)
    fn = rng.uniform(20.0, 50.0)
    zeta = rng.uniform(0.01, 0.04)
    peak = rng.uniform(50e-6, 150e-6)
    direction = ("run-up", "coast-down")[int(rng.integers(2))]
    lo, hi = 0.3 * fn, 1.8 * fn
    f_from, f_to = (lo, hi) if direction == "run-up" else (hi, lo)
    rotor = Rotor(m=rng.uniform(1.0, 20.0), fn=fn, zeta=zeta, e=2 * zeta * peak, beta=rng.uniform(0, 2 * math.pi),
                  nu=rng.uniform(0, 2 * math.pi), f_from=f_from, f_to=f_to, duration=rng.uniform(8.0, 11.0),
                  phi0=rng.uniform(0, 2 * math.pi), fault=case if case not in ("healthy", "runout") else "healthy",
                  profile=profile)
    daq = {"fs": float(fs) if fs else float(SAMPLE_RATES[int(rng.integers(len(SAMPLE_RATES)))]),
           "direction": direction, "gaps_um": (float(rng.uniform(900, 1400)), float(rng.uniform(900, 1400)))}
    k = rotor.k
    p: dict = {}
    if case == "asymmetry":
        p = {"D": rng.uniform(0.02, 0.04), "psi": rng.uniform(0, math.pi)}
    elif case == "breathing_crack":
        p = {"dk": rng.uniform(0.02, 0.06), "psi": rng.uniform(0, 2 * math.pi), "load_N": rotor.m * G,
             "load_dir": DOWN, "law": crack_law}
    elif case == "breathing_crack_side":
        d = rng.uniform(15e-6, 40e-6)
        p = {"dk": rng.uniform(0.05, 0.1), "psi": rng.uniform(0, 2 * math.pi), "load_N": k * d,
             "load_dir": rng.uniform(0, 2 * math.pi), "law": crack_law}
    elif case == "rub":
        p = {"kr": rng.uniform(0.5, 2.0) * k, "mu": rng.uniform(0.1, 0.3), "clearance_share": rng.uniform(0.45, 0.75)}
    elif case == "shaft_bow":
        p = {"b": rng.uniform(5e-6, 15e-6), "psi": rng.uniform(0, 2 * math.pi)}
    elif case == "support_anisotropy":
        p = {"s": rng.uniform(0.04, 0.08), "chi": rng.uniform(0, math.pi)}
    elif case == "cross_coupled_stiffness":
        p = {"q": rng.uniform(0.3, 0.6) * rotor.c * rotor.wn}
    elif case == "gravity":
        p = {"load_N": rotor.m * G, "load_dir": DOWN}
    elif case == "runout":
        daq["runout"] = tuple((float(rng.uniform(3.0, 8.0)), float(rng.uniform(0, 2 * math.pi))) for _ in PROBE_DEG)
    elif case in ("two_modes", "two_modes_crack"):
        mu, ratio = rng.uniform(0.5, 1.5), rng.uniform(1.3, 2.5)
        kc = (rotor.m * (ratio * rotor.wn) ** 2 - k) / (1 + 1 / mu)
        p = {"mu": mu, "ratio": ratio, "kc": kc, "e2": rotor.e * rng.uniform(0.5, 2.0),
             "beta2": rng.uniform(0, 2 * math.pi)}
        if case == "two_modes_crack":
            p.update(D=rng.uniform(0.03, 0.06), psi=rng.uniform(0, math.pi))
    if psi_deg is not None and "psi" in p:
        p["psi"] = math.radians(psi_deg)
    return replace(rotor, p=p), daq


def sample_times(r: Rotor, fs: float) -> np.ndarray:
    return np.arange(int(r.duration * fs) + 1) / fs


def keyphasor(r: Rotor, t: np.ndarray) -> np.ndarray:
    """Ideal square notch: 0 V while the notch (body angles nu - 4 % turn .. nu) passes the
    keyphasor probe at fixed angle 0, 5 V elsewhere; leading edge at phi + nu = 0 (mod 2 pi)."""
    frac = np.mod(r.phi(t) + r.nu, 2 * math.pi) / (2 * math.pi)
    return np.where(frac < NOTCH_FRACTION, 0.0, KP_HIGH_V)


def probe_readings(rec: Record, t: np.ndarray, xy: np.ndarray) -> dict[str, np.ndarray]:
    """Each probe's reading (um): displacement towards it, DC gap, runout, noise."""
    rng = np.random.default_rng([rec.seed, CASES.index(rec.case), int(round(rec.noise_um * 1e6)), 7])
    out = {}
    phi = rec.rotor.phi(t)
    for i, (name, deg) in enumerate(PROBE_DEG.items()):
        a = math.radians(deg)
        x = (xy[0] * math.cos(a) + xy[1] * math.sin(a)) * 1e6 + rec.gaps_um[i]
        if rec.runout:
            amp, ang = rec.runout[i]
            x = x + amp * np.cos(a - phi - rec.rotor.nu - ang)
        n = rng.normal(0.0, rec.noise_um, len(t))
        if rec.colour:
            w = rng.normal(0.0, rec.noise_um * math.sqrt(1 - rec.colour ** 2), len(t))
            from scipy.signal import lfilter
            n = n + lfilter([1.0], [1.0, -rec.colour], w)
        out[name] = x + n
    return out


def filter_channel(x: np.ndarray, fs: float) -> np.ndarray:
    """A DAQ's analog anti-alias filter, the same on every channel (``--anti-alias``): a 4-pole
    Butterworth low-pass at ``fs / 2.56`` (the vibration analysers' convention: the useful
    band to ``fs / 2.56``), causal, started settled at the channel's first value.  It colours
    the noise (rolled off towards Nyquist) and delays every channel alike."""
    from scipy.signal import butter, sosfilt, sosfilt_zi

    sos = butter(4, 2.0 / 2.56, output="sos")
    return sosfilt(sos, x, zi=sosfilt_zi(sos) * x[0])[0]


def true_noise_um(rec: Record) -> float:
    return rec.noise_um * (math.sqrt(2.0) if rec.colour else 1.0)


def orbit_peak(xy: np.ndarray) -> float:
    """Largest radius of the orbit about its mean (m)."""
    return float(np.hypot(xy[0] - xy[0].mean(), xy[1] - xy[1].mean()).max())


def make_record(case: str, seed: int, noise_um: float, *, fs: float | None = None, colour: float = 0.0,
                crack_law: str = "mayes", psi_deg: float | None = None,
                profile: str = "linear", anti_alias: bool = False) -> tuple[Record, np.ndarray, dict]:
    """Simulate one record: the :class:`Record`, its sample times, its columns and the truth."""
    rotor, daq = draw_rotor(seed, case, fs=fs, crack_law=crack_law, psi_deg=psi_deg, profile=profile)
    t = sample_times(rotor, daq["fs"])
    truth: dict = {}
    if case == "rub":
        healthy = replace(rotor, fault="healthy", p={})
        peak = orbit_peak(integrate(healthy, t))
        p = dict(rotor.p)
        p["delta"] = p["clearance_share"] * peak
        rotor = replace(rotor, p=p)
        truth["healthy_peak_um"] = peak * 1e6
    rec = Record(case=case, seed=seed, noise_um=float(noise_um), fs=daq["fs"], rotor=rotor, direction=daq["direction"],
                 colour=colour, gaps_um=daq["gaps_um"], runout=daq.get("runout", ()), anti_alias=anti_alias)
    xy = integrate(rotor, t)
    cols = {"t": t, "kp": keyphasor(rotor, t), **probe_readings(rec, t, xy)}
    if anti_alias:
        cols.update({k: filter_channel(v, rec.fs) for k, v in cols.items() if k != "t"})
    truth.update(describe_truth(rec, xy))
    return rec, t, {"columns": cols, "truth": truth}


def describe_truth(rec: Record, xy: np.ndarray) -> dict:
    r = rec.rotor
    p = r.p
    d = {"m_kg": r.m, "fn_hz": r.fn, "critical_rpm": r.fn * 60, "zeta": r.zeta, "e_um": r.e * 1e6,
         "rpm_from": r.f_from * 60, "rpm_to": r.f_to * 60, "duration_s": r.duration, "direction": rec.direction,
         "peak_um": orbit_peak(xy) * 1e6, "notch_body_deg": math.degrees(r.nu),
         "heavy_spot_deg": math.degrees(r.beta - r.nu) % 360.0}
    deg = math.degrees
    if rec.case == "asymmetry":
        d.update(D=p["D"], axis_deg=deg(p["psi"]), text=f"D={p['D']:.4f} stiff axis {deg(p['psi']):.1f} deg")
    elif rec.case.startswith("breathing_crack"):
        sag = p["load_N"] / r.k * 1e6
        d.update(dk=p["dk"], axis_deg=deg(p["psi"]) % 360, law=p["law"], static_deflection_um=sag,
                 load_dir_deg=deg(p["load_dir"]) % 360,
                 text=f"dk/k={p['dk']:.4f} crack {deg(p['psi']) % 360:.1f} deg, {p['law']}, sag {sag:.0f} um")
    elif rec.case == "rub":
        d.update(clearance_um=p["delta"] * 1e6, kr_over_k=p["kr"] / r.k, mu=p["mu"],
                 text=f"clearance {p['delta'] * 1e6:.0f} um ({p['clearance_share']:.2f} of healthy peak), "
                      f"kr={p['kr'] / r.k:.2f}k mu={p['mu']:.2f}")
    elif rec.case == "shaft_bow":
        d.update(bow_um=p["b"] * 1e6, axis_deg=deg(p["psi"]) % 360,
                 text=f"bow {p['b'] * 1e6:.1f} um at {deg(p['psi']) % 360:.1f} deg")
    elif rec.case == "support_anisotropy":
        d.update(s=p["s"], axis_deg=deg(p["chi"]),
                 text=f"s={p['s']:.3f} stiff support axis {deg(p['chi']):.1f} deg from x")
    elif rec.case == "cross_coupled_stiffness":
        d.update(q_over_c_wn=p["q"] / (r.c * r.wn), q_over_k=p["q"] / r.k,
                 text=f"q={p['q'] / r.k:.4f}k ({p['q'] / (r.c * r.wn):.2f} c wn)")
    elif rec.case == "gravity":
        d.update(static_deflection_um=p["load_N"] / r.k * 1e6, text=f"sag {p['load_N'] / r.k * 1e6:.0f} um")
    elif rec.case in ("two_modes", "two_modes_crack"):
        d.update(second_critical_rpm=r.fn * p["ratio"] * 60, mass_ratio=p["mu"],
                 text=f"second mode {r.fn * p['ratio'] * 60:.0f} rpm ({p['ratio']:.2f} fn), mass ratio {p['mu']:.2f}")
        if "D" in p:
            # the second mode [1, -1/mu] (modal stiffness (1 + 1/mu) r^2 k) sees D / ((1 + 1/mu) r^2)
            d.update(D=p["D"] / (1 + p["mu"]), D_shaft=p["D"], axis_deg=deg(p["psi"]),
                     D_second_mode=p["D"] / ((1 + 1 / p["mu"]) * p["ratio"] ** 2),
                     text=d["text"] + f"; crack D={p['D']:.4f} (first mode D={p['D'] / (1 + p['mu']):.4f}, second "
                                      f"{p['D'] / ((1 + 1 / p['mu']) * p['ratio'] ** 2):.4f}) "
                                      f"stiff axis {deg(p['psi']):.1f} deg")
    elif rec.case == "runout":
        d.update(runout=[(a, deg(b) % 360) for a, b in rec.runout],
                 text="runout " + ", ".join(f"{a:.1f} um @ {deg(b) % 360:.0f}" for a, b in rec.runout))
    else:
        d["text"] = "-"
    d["text"] = f"{d['text']} (fn {r.fn:.1f} Hz, zeta {r.zeta:.3f}, peak {d['peak_um']:.0f} um)"
    return d


def write_record(folder: Path, name: str, columns: dict) -> tuple[Path, Path]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    rig_path = folder / f"{name}_rig.json"
    rig_path.write_text(json.dumps(RIG))
    data_path = folder / f"{name}.parquet"
    pq.write_table(pa.table({k: np.asarray(v, dtype=float) for k, v in columns.items()}), data_path)
    return rig_path, data_path


# ------------------------------------------------------------------ diagnosis and comparison
def _wrap(deg: float, period: float) -> float:
    return float((deg + period / 2) % period - period / 2)


def crack_comparison(case: str, truth: dict, params: dict, own_rpm: float | None = None) -> dict:
    """A named crack's size and axis against the truth (the axis from the notch in the
    direction of rotation).  On the two-disk rotor the size is the crack's share of the mode
    the diagnosis holds as its own (``own_rpm``, its natural frequency): the package's ``D``
    is relative to that mode's stiffness, and with both criticals in the run either may be it."""
    if case == "two_modes_crack" and own_rpm and "D_second_mode" in truth:
        first, second = truth["critical_rpm"], truth["second_critical_rpm"]
        if abs(math.log(own_rpm / second)) < abs(math.log(own_rpm / first)):
            truth = {**truth, "D": truth["D_second_mode"]}
    if case in ("asymmetry", "two_modes_crack"):
        if "asymmetry" in params:
            v = params["asymmetry"]["values"]
            D, ax, via = float(v["D"]), math.degrees(float(v.get("D_axis", 0.0))), "asymmetry"
        elif "breathing_crack" in params:
            v = params["breathing_crack"]["values"]
            D, ax, via = float(v["dk_crack"]) / 4, math.degrees(float(v.get("crack_axis", 0.0))) + 90.0, "breathing_crack"
        else:
            return {}
        if D < 0:  # the same asymmetry seen from its soft axis
            D, ax = -D, ax + 90.0
        return {"as": via, "size": D, "true_size": truth["D"], "size_error": abs(D / truth["D"] - 1.0),
                "axis_deg": ax % 180.0, "true_axis_deg": truth["axis_deg"],
                "axis_error_deg": abs(_wrap(ax - truth["axis_deg"], 180.0))}
    if case.startswith("breathing_crack"):
        if "hinge_crack" in params:  # the mouth's direction: which side opens is known (mod 360)
            v = params["hinge_crack"]["values"]
            dk, ax = float(v["dk_hinge"]), math.degrees(float(v.get("hinge_axis", 0.0)))
            return {"as": "hinge_crack", "size": dk, "true_size": truth["dk"],
                    "size_error": abs(dk / truth["dk"] - 1.0), "axis_deg": ax % 360.0,
                    "true_axis_deg": truth["axis_deg"], "axis_error_deg": abs(_wrap(ax - truth["axis_deg"], 360.0))}
        if "breathing_crack" in params:
            v = params["breathing_crack"]["values"]
            dk, ax, via = float(v["dk_crack"]), math.degrees(float(v.get("crack_axis", 0.0))), "breathing_crack"
        elif "asymmetry" in params:  # the open part only: dk/4 = D, weak axis 90 deg from the stiff
            v = params["asymmetry"]["values"]
            D, axs = float(v["D"]), math.degrees(float(v.get("D_axis", 0.0)))
            if D < 0:
                D, axs = -D, axs + 90.0
            dk, ax, via = 4 * D, axs + 90.0, "asymmetry"
        else:
            return {}
        return {"as": via, "size": dk, "true_size": truth["dk"], "size_error": abs(dk / truth["dk"] - 1.0),
                "axis_deg": ax % 360.0, "true_axis_deg": truth["axis_deg"],
                "axis_error_deg": abs(_wrap(ax - truth["axis_deg"], 180.0))}
    return {}


def estimates(case: str, truth: dict, params: dict) -> dict:
    """What the diagnosis says of the unbalance and of a non-crack fault, beside the truth.

    Unbalance: the package's translation model forces with ``(phidd + i phid^2) e^{i(phi + beta)}``,
    i.e. the heavy spot at ``beta + 90 deg`` from the notch (in its sense); ``tau`` is ``e`` in mm."""
    out: dict = {}
    u = (params.get("unbalance") or {}).get("values")
    if u:
        out["unbalance"] = {"e_um": 1e3 * float(u["tau"]), "true_e_um": truth["e_um"],
                            "heavy_spot_deg": (math.degrees(float(u["beta"])) + 90.0) % 360.0,
                            "true_heavy_spot_deg": truth["heavy_spot_deg"]}
    if case == "rub" and "rub" in params:
        v = params["rub"]["values"]
        out["rub"] = {"clearance_um": 1e3 * float(v["rub_clearance"]), "true_clearance_um": truth["clearance_um"],
                      "kr_over_k": float(v["rub_stiffness"]), "true_kr_over_k": truth["kr_over_k"],
                      "mu": float(v["rub_friction"]), "true_mu": truth["mu"]}
    if case == "support_anisotropy" and "support_anisotropy" in params:
        v = params["support_anisotropy"]["values"]
        s, ax = float(v["support_anisotropy"]), math.degrees(float(v.get("support_axis", 0.0)))
        if s < 0:
            s, ax = -s, ax + 90.0
        out["support_anisotropy"] = {"s": s, "true_s": truth["s"], "axis_deg": ax % 180.0,
                                     "true_axis_deg": truth["axis_deg"]}
    if case == "shaft_bow" and "shaft_bow" in params:
        v = params["shaft_bow"]["values"]
        out["shaft_bow"] = {"bow_um": 1e3 * float(v["bow"]), "true_bow_um": truth["bow_um"],
                            "angle_deg": math.degrees(float(v.get("bow_phase", 0.0))) % 360.0,
                            "true_angle_deg": truth["axis_deg"]}
    if case == "cross_coupled_stiffness" and "cross_coupled_stiffness" in params:
        v = params["cross_coupled_stiffness"]["values"]
        out["cross_coupled_stiffness"] = {"q_over_k": float(v["cross_coupling"]), "true_q_over_k": truth["q_over_k"]}
    return out


def second_mode_estimate(truth: dict, d: dict) -> dict:
    """The second mode the waveforms' model holds (``d["second_mode"]``) beside the two-disk
    rotor's, where the diagnosis reports one."""
    got = d.get("second_mode")
    if not got or "second_critical_rpm" not in truth:
        return {}
    # which of the two is "second" is the diagnosis's choice (its model's own mode follows the
    # 1X vectors' highest peak): compared with the nearer of the simulator's two modes
    rpm = got["natural_frequency_rpm"]
    true = min((truth["critical_rpm"], truth["second_critical_rpm"]), key=lambda r: abs(math.log(r / rpm)))
    return {"second_mode": {"rpm": rpm, "rpm_ci95": got["natural_frequency_rpm_ci95"],
                            "zeta": got["damping_ratio"], "true_rpm": true}}


def _estimate_cell(o: dict) -> str:
    parts = []
    for name, v in (o.get("estimates") or {}).items():
        if name == "second_mode":
            parts.append(f"second mode {v['rpm']:.0f} +- {v['rpm_ci95']:.0f}/{v['true_rpm']:.0f} rpm, "
                         f"zeta {v['zeta']:.4f}")
        elif name == "unbalance":
            parts.append(f"e {v['e_um']:.2f}/{v['true_e_um']:.2f} um, heavy spot "
                         f"{v['heavy_spot_deg']:.0f}/{v['true_heavy_spot_deg']:.0f} deg")
        elif name == "rub":
            parts.append(f"clearance {v['clearance_um']:.1f}/{v['true_clearance_um']:.1f} um, kr "
                         f"{v['kr_over_k']:.2f}/{v['true_kr_over_k']:.2f} k, mu {v['mu']:.2f}/{v['true_mu']:.2f}")
        elif name == "support_anisotropy":
            parts.append(f"s {v['s']:.4f}/{v['true_s']:.4f}, axis {v['axis_deg']:.1f}/{v['true_axis_deg']:.1f} deg")
        elif name == "shaft_bow":
            parts.append(f"bow {v['bow_um']:.1f}/{v['true_bow_um']:.1f} um")
        elif name == "cross_coupled_stiffness":
            parts.append(f"q {v['q_over_k']:.4f}/{v['true_q_over_k']:.4f} k")
    return "; ".join(parts) or "-"


def diagnose_files(rig_path: Path, data_path: Path) -> tuple[dict, float]:
    """``diagnose_rig(load_waveforms(data, load_rig(rig)))`` as a dict, and its wall time."""
    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose_rig(load_waveforms(data_path, load_rig(rig_path))).to_dict()
    return d, time.perf_counter() - t0


def judge(case: str, truth: dict, d: dict, true_noise: float) -> dict:
    """The outcome of one diagnosis against the truth."""
    named = list(d.get("missing") or [])
    vec_missing = list((d.get("vectors") or {}).get("missing") or [])
    params = d.get("parameters") or {}
    expected, tolerated = EXPECTED[case], TOLERATED.get(case, ())
    extra = [e for e in named if e not in expected and e not in tolerated]
    if expected:
        right = any(e in named for e in expected) and not extra
        missed = not any(e in named for e in expected)
    else:
        right, missed = not extra, False
        if case == "runout":
            right = right and "runout" in vec_missing
    floor = d.get("noise_floor")
    undecidable = d.get("undecidable") or {}
    return {"named": named, "vectors_missing": vec_missing, "verdict": d.get("verdict"),
            "noise_floor": floor, "floor_ratio": (floor / true_noise) if floor else None,
            "rms_ratio_before": d.get("rms_ratio_before"), "rms_ratio_after": d.get("rms_ratio_after"),
            "right": bool(right), "missed": bool(missed), "wrong_named": extra,
            "said_undecidable": bool(missed) and any(e in undecidable for e in expected),
            "estimates": {**estimates(case, truth, params), **second_mode_estimate(truth, d)},
            "crack_named_falsely": case not in CRACK_CASES and any(c in named for c in CRACKS),
            "crack": crack_comparison(case, truth, params, d.get("natural_frequency_rpm")), "parameters": params,
            "rejected": d.get("rejected"), "undecidable": d.get("undecidable"), "notes": d.get("notes")}


def run_one(case: str, seed: int, noise_um: float, *, fs: float | None = None, colour: float = 0.0,
            crack_law: str = "mayes", psi_deg: float | None = None, keep: Path | None = None,
            profile: str = "linear", anti_alias: bool = False) -> dict:
    """Simulate, write, read back and diagnose one record; its outcome (JSON-able)."""
    t0 = time.perf_counter()
    try:
        rec, t, made = make_record(case, seed, noise_um, fs=fs, colour=colour, crack_law=crack_law, psi_deg=psi_deg,
                                   profile=profile, anti_alias=anti_alias)
    except SimulatorUnstable as exc:  # no record to diagnose: said apart, not a product error
        rotor, daq = draw_rotor(seed, case, fs=fs, crack_law=crack_law, psi_deg=psi_deg, profile=profile)
        return {"case": case, "seed": seed, "noise_um": noise_um, "fs": daq["fs"], "colour": colour,
                "unstable": str(exc), "right": False, "simulation_s": time.perf_counter() - t0,
                "truth": {"text": f"{case} (simulator unstable)"}}
    sim_s = time.perf_counter() - t0
    out = {"case": case, "seed": seed, "noise_um": noise_um, "fs": rec.fs, "colour": colour,
           "true_noise_um": true_noise_um(rec), "truth": made["truth"], "simulation_s": sim_s,
           "rotor": {**{k: v for k, v in asdict(rec.rotor).items() if k != "p"},
                     "p": {k: v for k, v in rec.rotor.p.items()}}}
    name = f"{case}_s{seed}_n{noise_um:g}"
    with tempfile.TemporaryDirectory(prefix="foreign_rig_") as tmp:
        folder = keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        rig_path, data_path = write_record(folder, name, made["columns"])
        try:
            d, diag_s = diagnose_files(rig_path, data_path)
        except Exception as exc:  # an error is an outcome
            out.update(error=f"{type(exc).__name__}: {exc}", right=False)
            return out
    out["diagnosis_s"] = diag_s
    out.update(judge(case, made["truth"], d, out["true_noise_um"]))
    return out


# ------------------------------------------------------------------ the table
def _crack_cell(o: dict) -> str:
    c = o.get("crack") or {}
    if not c:
        return "-"
    return (f"{c['size']:.4f} vs {c['true_size']:.4f} ({c['size_error'] * 100:.1f} %); axis {c['axis_deg']:.1f} "
            f"vs {c['true_axis_deg']:.1f} deg: err {c['axis_error_deg']:.1f}"
            f" [as {c['as']}]")


def table(outcomes: list[dict]) -> str:
    lines = ["| case | noise (um) | fs (kHz) | truth | named | verdict (residual / floor) | floor / true noise | "
             "crack: size, axis reported vs truth | other estimates (reported/true) | crack for a non-crack | right | "
             "diagnosis (s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for o in outcomes:
        if "unstable" in o:
            lines.append(f"| {o['case']} | {o['noise_um']:g} | {o['fs'] / 1000:g} | {o['truth']['text']} | "
                         f"not diagnosed: the simulator diverged ({o['unstable'][:100]}) | - | - | - | - | - | - | - |")
            continue
        if "error" in o:
            lines.append(f"| {o['case']} | {o['noise_um']:g} | {o['fs'] / 1000:g} | {o['truth']['text']} | ERROR "
                         f"{o['error'][:120]} | - | - | - | - | - | no | - |")
            continue
        fr = o.get("floor_ratio")
        rr = f"{o['rms_ratio_after']:.2f}" if o.get("rms_ratio_after") is not None else "-"
        lines.append(f"| {o['case']} | {o['noise_um']:g} | {o['fs'] / 1000:g} | {o['truth']['text']} | "
                     f"{', '.join(o['named']) or 'nothing'} | {o['verdict']} ({rr}) | "
                     f"{(f'{fr:.2f}' if fr else '-')} | {_crack_cell(o)} | {_estimate_cell(o)} | "
                     f"{'YES' if o['crack_named_falsely'] else 'no'} | "
                     f"{'yes' if o['right'] else ('no, said undecidable' if o['said_undecidable'] else 'NO')} | "
                     f"{o['diagnosis_s']:.0f} |")
    return "\n".join(lines)


def problems(outcomes: list[dict]) -> list[str]:
    out = []
    for o in outcomes:
        head = f"{o['case']} at {o['noise_um']:g} um ({o['fs'] / 1000:g} kHz, seed {o['seed']})"
        if "unstable" in o:
            continue  # no record was made: listed apart in main
        if "error" in o:
            out.append(f"{head}: ERROR {o['error']}")
            continue
        why = []
        if o["missed"]:
            why.append(f"missed (expected one of {EXPECTED[o['case']]})"
                       + (", said undecidable" if o["said_undecidable"] else ""))
        if o["wrong_named"]:
            why.append(f"named wrongly {o['wrong_named']}")
        if o["crack_named_falsely"]:
            why.append("a crack named for a non-crack")
        if o["case"] == "runout" and "runout" not in o["vectors_missing"]:
            why.append("runout not named by the 1X vectors")
        fr = o.get("floor_ratio")
        if fr is None or not (1 / 1.5 <= fr <= 1.5):
            why.append(f"floor ratio {fr if fr is None else round(fr, 2)} outside 1.5x")
        c = o.get("crack") or {}
        if c and (c["size_error"] > 0.05 or c["axis_error_deg"] > 5.0):
            why.append(f"crack size error {c['size_error'] * 100:.1f} %, axis error {c['axis_error_deg']:.1f} deg")
        if why:
            out.append(f"{head}: " + "; ".join(why) + f" -- named {o['named'] or 'nothing'}, verdict {o['verdict']}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise", default="0.5,1", help="probe noise std, um (comma-separated)")
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {', '.join(CASES)}")
    ap.add_argument("--fs", type=float, default=None, help="sample rate, Hz (default drawn per case)")
    ap.add_argument("--colour", type=float, default=0.0, help="AR(1) coefficient of an added coloured noise")
    ap.add_argument("--crack-law", choices=("mayes", "gasch"), default="mayes")
    ap.add_argument("--profile", choices=("linear", "motor", "updown"), default="linear",
                    help="the speed's course: constant acceleration, a motor's (fast first, slow at the end), or "
                         "updown (there, a dwell, and back in one record)")
    ap.add_argument("--anti-alias", action="store_true",
                    help="every channel (keyphasor and probes) through a DAQ's 4-pole Butterworth at fs / 2.56")
    ap.add_argument("--keep", default=None, help="folder to keep the written records in")
    ap.add_argument("--out", default=None, help="JSON of every outcome")
    args = ap.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    bad = [c for c in cases if c not in CASES]
    if bad:
        ap.error(f"unknown cases {bad}; known: {', '.join(CASES)}")
    noises = [float(x) for x in args.noise.split(",") if x]
    if not (0.0 <= args.colour < 1.0):
        ap.error("--colour: an AR(1) coefficient in [0, 1)")
    from rotor_env.results import jsonable

    outcomes = []
    t0 = time.perf_counter()
    total = len(cases) * len(noises)
    for case in cases:
        for noise in noises:
            o = run_one(case, args.seed, noise, fs=args.fs, colour=args.colour, crack_law=args.crack_law,
                        keep=Path(args.keep) if args.keep else None, profile=args.profile,
                        anti_alias=args.anti_alias)
            outcomes.append(o)
            status = ("SIMULATOR UNSTABLE " + o["unstable"]) if "unstable" in o else ("ERROR " + o["error"]) if "error" in o else (
                f"{'ok ' if o['right'] else 'BAD'} named {o['named']} floor {o['floor_ratio'] or math.nan:.2f}x "
                f"sim {o['simulation_s']:.0f} s diag {o['diagnosis_s']:.0f} s")
            print(f"[{len(outcomes)}/{total} {time.perf_counter() - t0:.0f} s] {case} {noise:g} um "
                  f"{o['fs'] / 1000:g} kHz: {status}", file=sys.stderr, flush=True)
            if args.out:
                Path(args.out).write_text(json.dumps(jsonable({"argv": argv if argv is not None else sys.argv[1:],
                                                               "outcomes": outcomes}), indent=1))
    print(table(outcomes))
    print("\nProblems (missed, wrong effect, crack for a non-crack, floor outside 1.5x, crack > 5 % / 5 deg):")
    for line in problems(outcomes) or ["none"]:
        print(f"- {line}")
    unstable = [o for o in outcomes if "unstable" in o]
    if unstable:
        print("\nNot diagnosed, the foreign simulator's own motion diverged (a drawn rotor, not the product):")
        for o in unstable:
            print(f"- {o['case']} at {o['noise_um']:g} um (seed {o['seed']}): {o['unstable']}")
    print(f"\n{len(outcomes)} records in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
