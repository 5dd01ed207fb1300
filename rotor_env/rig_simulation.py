"""Simulated rig recordings: the model's run written as a rig would record it.

The simulator runs in dimensionless units; a natural frequency (rpm) maps its time to
seconds, :data:`~rotor_env.measurements.waveforms.LENGTH_UNIT` its translation to metres.  The output is what
a data acquisition system writes — time in s, a keyphasor pulse (a notch: the signal
dips from 0 to -5 V for 1/20 of a turn) and each probe's reading (in the rig's unit,
with its DC gap, optional runout and Gaussian noise; the notch's edges ramp over 1/100
of a turn, as a probe tip a few millimetres wide sees a notch) — or what a condition-monitoring
system exports: the order-tracked vectors per revolution (:class:`~rotor_env.measurements.vectors.VectorTable`).
Everything is reproducible from ``seed``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .measurements.rig import SPEED_UNITS, Rig
from .measurements.vectors import VectorTable, order_track
from .measurements.waveforms import LENGTH_UNIT
from .params import RotorParams
from .simulator import RunUp, Simulator

__all__ = ["RigRun", "simulate_rig"]

KEYPHASOR_LOW = -5.0
KEYPHASOR_WIDTH = 0.05  #: of a turn
KEYPHASOR_RAMP = 0.01  #: of a turn, each edge
GAP_VOLTS = -10.0


@dataclass(frozen=True)
class RigRun:
    """A simulated run: its columns (as a file would hold them) and the truth."""

    columns: dict[str, np.ndarray]
    natural_rpm: float
    params: RotorParams

    def vectors(self, rig: Rig, orders: tuple[int, ...] = (1, 2)) -> VectorTable:
        """The order-tracked table of the probes (per revolution, lead convention); for a
        one-plane rig only (a tilt rig's table is :meth:`RigRecord.vectors` of the loaded file)."""
        if rig.model == "tilt":
            raise ValueError("the 1X table of a two-plane rig is the tilt's: load the waveforms and use "
                             "RigRecord.vectors()")
        t = self.columns["t"]
        phi = self.columns["_phi"]
        names = tuple(p.name for p in rig.probes)
        X = np.column_stack([self.columns[n] for n in names])
        if rig.displacement in ("V", "mV"):
            X = np.column_stack([rig.to_metres(X[:, j] - np.mean(X[:, j])) / 1e-6 for j in range(X.shape[1])])
        tr = order_track(t, X - X.mean(axis=0), phi, orders)
        return VectorTable(speed=tr.speed, t=tr.t, probes=names, vectors=tr.vectors, amp_unit=rig.amp_unit,
                           angles=np.array([p.angle for p in rig.probes]), source="simulated")

    def file_columns(self) -> dict[str, np.ndarray]:
        return {k: v for k, v in self.columns.items() if not k.startswith("_")}


def simulate_rig(
    rig: Rig,
    params: RotorParams,
    *,
    natural_rpm: float = 1650.0,
    rpm_from: float = 300.0,
    rpm_to: float = 3000.0,
    rpm_per_s: float = 230.0,
    sample_rate: float = 5000.0,
    noise: float = 0.0,
    runout: float | Mapping[str, float] = 0.0,
    runout_phase_deg: float | Mapping[str, float] = 0.0,
    lines: Sequence[tuple[float, float]] = (),
    scratch: float = 0.0,
    sensitivity: Mapping[str, float] | None = None,
    angle_error_deg: Mapping[str, float] | None = None,
    drift: float = 0.0,
    flicker_hz: float = 0.0,
    seed: int | None = None,
) -> RigRun:
    """Simulate a start-up (``rpm_per_s > 0``) or coast-down (``< 0``) as the rig records it.

    ``noise`` and ``runout`` are in the rig's displacement unit (um, mil, ...; for volts, in
    um); the runout is a 1X pattern fixed to the shaft, the same vector for every probe of a
    plane seen from its own angle, as a scratch on the probe track.  A mapping plane ->
    value gives each plane's track its own runout (a real shaft's tracks differ; the same
    runout on both planes of a tilt rig is a parallel offset, which the planes' difference
    cancels).

    Instrument artefacts (:mod:`rotor_env.measurements.artefacts` takes them out):
    ``lines``: ``(frequency Hz, amplitude)`` pairs, sinusoids that do not follow the shaft
    (mains hum and its harmonics), each probe with its own phase drawn from ``seed``;
    ``scratch``: a narrow mark on each plane's track (its own angle on each, drawn from
    ``seed``), a raised-cosine pulse of this height 1/12 of a turn wide, every probe seeing it at
    its own angle -- a runout pattern with harmonics far above 2X (to order 96, those below 0.4
    of the sample rate: the acquisition's anti-alias filter).  ``sensitivity``: probe -> its
    true sensitivity over the one the rig file gives (1.02: reads 2 % high);
    ``angle_error_deg``: probe -> how far its true mounting angle is from the rig file's.
    ``drift``: the probes' slowly moving mean (:mod:`rotor_env.measurements.drift` takes it
    out), in the rig's displacement unit: each plane's shaft centreline moves by this much,
    in a direction of its own, as the square of the speed over the top speed (a shaft lifting
    on fluid-film bearings), and each probe's gap drifts linearly over the record by up to
    half of it (thermal growth).
    ``flicker_hz``: the probes' 1/f (flicker) noise corner: each probe's noise density is the
    white ``noise``'s times ``1 + flicker_hz / f`` (from the record's lowest frequency up; a
    driver's electronics, a cable's triboelectric noise) -- noise in the rotor's band that the
    band above it does not show (:func:`rotor_env.diagnosis.orders.off_order_noise` reads it).
    """
    def per_plane(v, plane) -> float:
        return float(v.get(plane, 0.0)) if isinstance(v, Mapping) else float(v)

    for name, v in (("natural_rpm", natural_rpm), ("rpm_from", rpm_from), ("rpm_to", rpm_to),
                    ("sample_rate", sample_rate)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive number, got {v!r}")
    if not math.isfinite(rpm_per_s) or rpm_per_s == 0 or (rpm_to - rpm_from) * rpm_per_s <= 0:
        raise ValueError(f"rpm_per_s = {rpm_per_s!r} does not go from {rpm_from:g} to {rpm_to:g} rpm")
    w_ref = natural_rpm * SPEED_UNITS["rpm"]
    duration = (rpm_to - rpm_from) / rpm_per_s
    n = int(round(duration * sample_rate))
    if n > 20_000_000:
        raise ValueError(f"{n} samples ({n * 8 * (len(rig.probes) + 2) / 1e9:.1f} GB): lower the sample rate")
    dt = 1.0 / sample_rate * w_ref
    a = rpm_per_s * SPEED_UNITS["rpm"] / w_ref**2
    s0 = rpm_from * SPEED_UNITS["rpm"] / w_ref
    sim = Simulator(params)
    # a machine runs at the first speed before the sweep starts: settle there first (ten
    # decay times of the damping), so the record holds no start-from-rest transient
    c = float(params.values.get("c", 0.03)) if "viscous_damping" in params.effects else 0.03
    settle = min(4000.0, 20.0 / max(c, 0.005))
    pre = sim.run(t_end=settle, dt=min(0.05, settle / 10), run_up=RunUp(rate=0.0, speed0=s0))
    last = pre.data[-1]
    initial = (last[4], last[5], last[6], last[7])
    meas = sim.run(t_end=n * dt, dt=dt, run_up=RunUp(rate=a, speed0=s0, phi0=float(last[1]) % (2 * math.pi)),
                   initial=initial)
    t = meas.t / w_ref
    phi = meas.phi
    if rig.model == "tilt":
        # a rigid disk tilting about its centre (axial position 0): a plane at z moves z * tilt
        u, v = meas.theta_y, meas.theta_x
    else:
        u = meas.theta_y * LENGTH_UNIT
        v = meas.theta_x * LENGTH_UNIT
    rng = np.random.default_rng(seed)
    # the artefacts' own draws: the noise of a seed stays what it was without them
    rng_art = np.random.default_rng(None if seed is None else [seed, 1])
    cols: dict[str, np.ndarray] = {"t": t}
    if rig.keyphasor is not None:
        frac = (phi / (2 * math.pi)) % 1.0
        # the notch: down from the pulse's angle (the edge crosses half depth there), up again
        down = np.clip(0.5 + frac / KEYPHASOR_RAMP, 0.0, 1.0)
        down = np.where(frac > 0.5, np.clip(0.5 + (frac - 1.0) / KEYPHASOR_RAMP, 0.0, 1.0), down)
        up = np.clip(0.5 + (frac - KEYPHASOR_WIDTH) / KEYPHASOR_RAMP, 0.0, 1.0)
        kp = KEYPHASOR_LOW * np.where(frac > 0.5, down, np.minimum(down, 1.0 - up))
        cols[rig.keyphasor] = kp
    else:
        cols[rig.speed] = meas.phi_dot * w_ref / SPEED_UNITS[rig.speed_unit]
    for f_hz, amp in lines:
        if not (math.isfinite(f_hz) and f_hz > 0 and math.isfinite(amp)):
            raise ValueError(f"lines: ({f_hz!r}, {amp!r}) is not a (positive frequency in Hz, amplitude) pair")
    line_phase = {(p.name, j): float(rng_art.uniform(0, 2 * math.pi)) for p in rig.probes for j in range(len(lines))}
    mark = {pl: float(rng_art.uniform(0, 2 * math.pi)) for pl in rig.plane_names}
    # the scratch's orders as the acquisition's anti-alias filter passes them: those below 0.4
    # of the sample rate at each instant (sampled as it is, its orders above Nyquist would fold
    # back into the band as noise no rig records)
    rev_hz = np.abs(meas.phi_dot) * w_ref / (2 * math.pi)
    if not math.isfinite(drift):
        raise ValueError(f"drift must be a finite number, got {drift!r}")
    lift = (rev_hz / max(float(np.max(rev_hz)), 1e-300)) ** 2
    lift_dir = {pl: float(rng_art.uniform(0, 2 * math.pi)) for pl in rig.plane_names}
    thermal = {p.name: float(rng_art.uniform(-0.5, 0.5)) for p in rig.probes}
    ramp = (t - t[0]) / max(float(t[-1] - t[0]), 1e-300)
    if not (math.isfinite(flicker_hz) and flicker_hz >= 0):
        raise ValueError(f"flicker_hz must be a number >= 0, got {flicker_hz!r}")
    flicker = {p.name: _flicker(len(t), sample_rate, flicker_hz, rng_art) * noise * _unit_um(rig)
               for p in rig.probes} if flicker_hz > 0 and noise > 0 else {}
    scratch_passed = [(order, c, order * rev_hz < 0.4 * sample_rate)
                      for order, c in enumerate(SCRATCH_ORDERS[1:], start=1)] if scratch else []
    for p in rig.probes:
        r = per_plane(runout, p.plane) * np.exp(1j * math.radians(per_plane(runout_phase_deg, p.plane)))
        angle = p.angle + math.radians((angle_error_deg or {}).get(p.name, 0.0))
        metres = (u * math.cos(angle) + v * math.sin(angle)) * (sensitivity or {}).get(p.name, 1.0)
        if rig.model == "tilt":
            metres = rig.planes[p.plane] * metres
        # the probe sees the track's runout at its own angle: phi - angle
        reading_um = metres / 1e-6 + np.real(r * np.exp(1j * (phi - p.angle))) * _unit_um(rig)
        reading_um = reading_um + rng.normal(0.0, noise * _unit_um(rig), len(t)) if noise > 0 else reading_um
        if flicker:
            reading_um = reading_um + flicker[p.name]
        if drift:
            reading_um = reading_um + drift * _unit_um(rig) * (
                lift * math.cos(p.angle - lift_dir[p.plane]) + thermal[p.name] * (2.0 * ramp - 1.0))
        for j, (f_hz, amp) in enumerate(lines):
            reading_um = reading_um + amp * _unit_um(rig) * np.cos(2 * math.pi * f_hz * t + line_phase[p.name, j])
        if scratch_passed:
            # the scratch: a raised cosine a twelfth of a turn wide, centred on the mark, under the probe
            d = phi - p.angle - mark[p.plane]
            for order, c, passed in scratch_passed:
                reading_um = reading_um + scratch * _unit_um(rig) * c * np.cos(order * d) * passed
        if rig.displacement in ("V", "mV"):
            volts_mv = reading_um * rig.sensitivity_mv_per_um + GAP_VOLTS * 1000.0
            cols[p.name] = volts_mv / (1000.0 if rig.displacement == "V" else 1.0)
        else:
            cols[p.name] = reading_um * 1e-6 / _metres(rig)
    cols["_phi"] = phi
    return RigRun(cols, natural_rpm, params)


def _flicker(n: int, sample_rate: float, corner_hz: float, rng: np.random.Generator) -> np.ndarray:
    """Unit white noise's 1/f companion: Gaussian noise whose one-sided density is a unit white
    noise's (``2 / sample_rate``) times ``corner_hz / f``, shaped in the frequency domain (the
    record's zero frequency left out)."""
    spec = rng.normal(size=n // 2 + 1) + 1j * rng.normal(size=n // 2 + 1)
    f = np.fft.rfftfreq(n, 1.0 / sample_rate)
    gain = np.zeros_like(f)
    gain[1:] = np.sqrt(corner_hz / f[1:])
    # irfft of unit complex Gaussian bins has variance 2 / n per bin pair: scaled to unit white
    return np.fft.irfft(spec * gain, n) * math.sqrt(n / 2.0)


def _scratch_orders(width: float = 1.0 / 12.0, orders: int = 96) -> np.ndarray:
    """Fourier cosine coefficients (orders 0..``orders``) of a raised-cosine mark of unit height
    ``width`` of a turn wide: the runout pattern of a scratch."""
    d = np.linspace(-math.pi, math.pi, 8192, endpoint=False)
    pulse = np.where(np.abs(d) < math.pi * width, 0.5 * (1 + np.cos(d / width)), 0.0)
    spec = np.fft.rfft(np.fft.ifftshift(pulse)) / len(d)
    return np.concatenate([[spec[0].real], 2 * spec[1:orders + 1].real])


#: a scratch's runout pattern by order (:func:`simulate_rig`'s ``scratch``)
SCRATCH_ORDERS = _scratch_orders()


def _metres(rig: Rig) -> float:
    return rig.to_metres(1.0) if rig.displacement not in ("V", "mV") else 1e-6


def _unit_um(rig: Rig) -> float:
    """One of the rig's reporting units in um."""
    return _metres(rig) / 1e-6
