"""The on-line monitor: samples in, the identified model and alarms out (Python API).

>>> mon = Monitor(effects=("unbalance", "asymmetry", "viscous_damping"))
>>> for chunk in chunks:                       # (m, 10) arrays of rotor_env.measurements.COLUMNS
...     for event in mon.update(chunk):
...         print(event)                        # {"event": "appeared", "effect": "asymmetry", ...}
>>> mon.save("state.npz"); mon = Monitor.load("state.npz")   # resumes bit for bit

The identifier is the project's :class:`~rotor_env.online.IdentificationCore` (both
equations, forgetting or a sliding window); the compiled block loop
(:mod:`rotor_env.monitor.kernel`) selects its rows and updates its factor with the
core's own functions.  The sequential test and its threshold are derived in
:mod:`rotor_env.monitor.detector`.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import threading
from collections.abc import Iterator
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from identifier.hac import chi2_log10_sf

from ..effects import EFFECTS
from ..measurements import COLUMNS
from ..measurements.files import MeasurementError, check_finite, check_time
from ..online import IdentificationCore
from ..outputs import atomic_write
from ..regression import DEFAULT_EFFECTS, build_rows
from . import kernel as K
from .detector import CusumDesign

__all__ = ["ALARM_EVENTS", "Monitor", "MonitorConfig", "alarm_words", "interrupts_held"]

_STATE_VERSION = 1
#: the kinds of event an alarm raises (the others: "status", "summary", "error")
ALARM_EVENTS = ("appeared", "changed", "disappeared", "unattributed")
#: the isolation's level: the deciding block must carry the change at this level, and an
#: effect whose own change explains the block within this level's margin of the best is a
#: candidate too (detector module docstring, *Isolation*)
ISOLATION_ALPHA = 0.01
#: a stream is said blind where fewer than this share of its blocks carried evidence, once the
#: calibration's blocks have passed (:attr:`Monitor.blind`)
BLIND_SHARE = 0.05
_N_COLS = len(COLUMNS)


def alarm_words(event: dict) -> str:
    """What an alarm names: its effect, or the effects the data could not tell apart."""
    if event.get("effect") is None and event.get("candidates"):
        return " or ".join(event["candidates"]) + " (which, the block cannot tell)"
    return str(event.get("effect"))


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Ctrl-C (SIGINT) held back until the block ends, then raised as ``KeyboardInterrupt``.

    A step that changes several parts of the monitor's state (or writes one output line)
    then either happens whole or not at all: an interrupt in its middle left a saved state
    that counted samples it never processed (a summary at t 0.0 beside a state at t 289.86)
    and status lines cut short.  Only where Python's own handler is in place, in the main
    thread (elsewhere a signal cannot be caught, or the program handles it itself).  A
    blocked write goes on after the signal (PEP 475), so a line is written whole.
    """
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt


@dataclass(frozen=True)
class MonitorConfig:
    """Options of :class:`Monitor` (times in samples unless said otherwise).

    effects: the model identified and watched, in nested order (library names).
    ip: the inertia ratio the regression uses.
    forgetting: ``lambda`` per *sample* (the memory is ``1/(1-lambda)`` samples); ignored
        with ``window``.
    window: a sliding window of this many samples instead of forgetting (rounded up to
        whole blocks; the rows leaving it are downdated out of the factor).
    arl0: target in-control average run length, samples between false alarms.
    block: samples per block of evidence.
    delta: the shift of the standardised block evidence the CUSUM is tuned for.
    noise_floor: the equation error's standard deviation is taken as at least this
        (noise-free simulated data: what is left is integration error).
    stick_speed, stick_sigmas: a sample counts only where the disk's relative speed
        exceeds ``max(stick_speed, stick_sigmas * its noise)`` (dry friction sticks it).
    hac_lags: Bartlett lags (regression rows) of the residual's long-run variance.
    identifiable_fraction: an effect's block counts only where the block alone sizes
        a change of it to this fraction of what its plausible bounds allow.
    calibration_blocks, calibration_memory: blocks before an effect's CUSUM runs, and
        the memory of its in-control calibration (batch means).
    restart: after an alarm the reference keeps this weight of its past.
    status_every: time between status events (``None``: none).
    """

    effects: tuple[str, ...] = DEFAULT_EFFECTS
    ip: float = 0.3
    forgetting: float = 0.9995
    window: int | None = None
    arl0: float = 1e7
    block: int = 200
    delta: float = 2.0
    noise_floor: float = 1e-4
    stick_speed: float = 1e-4
    stick_sigmas: float = 5.0
    hac_lags: int = 20
    identifiable_fraction: float = 0.1
    calibration_blocks: int = 20
    calibration_memory: int = 100
    restart: float = 1e-3
    status_every: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "effects", tuple(self.effects))
        for e in self.effects:
            if e not in EFFECTS:
                raise ValueError(f"unknown effect {e!r}; known effects: {', '.join(sorted(EFFECTS))}")
        checks = {
            "ip": 0.0 <= self.ip < 1.0,
            "forgetting": 0.0 < self.forgetting <= 1.0,
            "arl0": self.arl0 > self.block,
            "block": int(self.block) == self.block and self.block >= 20,
            "delta": self.delta > 0,
            "noise_floor": self.noise_floor >= 0,
            "hac_lags": int(self.hac_lags) == self.hac_lags and 0 <= self.hac_lags < self.block,
            "identifiable_fraction": self.identifiable_fraction > 0,
            "restart": 0.0 < self.restart <= 1.0,
        }
        if self.window is not None:
            checks["window"] = int(self.window) == self.window and self.window >= self.block
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"monitor option {name} = {getattr(self, name)!r} is out of range")

    @property
    def window_blocks(self) -> int:
        return 0 if self.window is None else -(-int(self.window) // self.block)


def _effect_scale(name: str) -> float:
    """The size of an effect its declared plausible bounds allow: the smallest finite half-range."""
    spans = [(p.upper - p.lower) / 2.0 for p in EFFECTS[name].parameters
             if math.isfinite(p.lower) and math.isfinite(p.upper)]
    return min(spans) if spans else 1.0


class Monitor:
    """Sequential detection of effects that appear, change or disappear, on a sample stream.

    ``update(chunk)`` takes an ``(m, 10)`` array (columns :data:`rotor_env.measurements.COLUMNS`,
    uniformly sampled, continuing the stream) and returns the events it raised: dicts
    ``{"event": "appeared" | "changed" | "disappeared", "effect", "t_alarm", "t_onset",
    "value_before", "value_after", "evidence"}`` (``"unattributed"``, ``"effect": None`` and
    ``"candidates"`` where the deciding block cannot tell which of several effects changed:
    :mod:`.detector`, *Isolation*) and, with ``status_every``, status
    dicts.  Samples are processed in whole blocks; the rest waits for the next chunk
    (the results do not depend on how the stream is cut).  A chunk that is not valid
    raises :class:`~rotor_env.measurements.files.MeasurementError` naming its row, and changes nothing.
    """

    def __init__(self, config: MonitorConfig | None = None, **options: Any) -> None:
        cfg = replace(config or MonitorConfig(), **options)
        self.config = cfg
        per_row = cfg.forgetting ** 0.5 if cfg.window is None else 1.0  # two rows per sample
        self.core = IdentificationCore(cfg.effects, equation="both", forgetting=per_row, prior=0.0,
                                       stick_speed=cfg.stick_speed, noise_floor=cfg.noise_floor)
        self.core.ip = float(cfg.ip)
        spec = self.core.spec
        self.effects = tuple(spec.groups)
        G, n = self.core._masks.shape
        self._q = np.array([len(c) for c in spec.groups.values()], dtype=np.int64)
        qmax = int(self._q.max())
        self._cols = np.zeros((G, qmax), dtype=np.int64)
        for g, names in enumerate(spec.groups.values()):
            self._cols[g, : len(names)] = [spec.columns.index(c) for c in names]
        self._scales = np.array([_effect_scale(e) for e in self.effects])
        self.design = CusumDesign(cfg.arl0, cfg.block, G, cfg.delta)
        self.threshold = self.design.threshold
        self._cfg = np.zeros(K.N_CFG)
        self._cfg[[K.C_LAMBDA, K.C_RTOL, K.C_FLOOR2, K.C_STICK, K.C_STICK_SIGMAS, K.C_IDENT_FRAC, K.C_K, K.C_H,
                   K.C_CAL_BLOCKS, K.C_CAL_W, K.C_RESTART, K.C_BLOCK, K.C_LAGS, K.C_MIN_ROWS, K.C_WINDOW]] = [
            per_row, self.core.estimator.rtol, cfg.noise_floor**2, cfg.stick_speed, cfg.stick_sigmas,
            cfg.identifiable_fraction, cfg.delta / 2.0, self.threshold, cfg.calibration_blocks,
            1.0 / cfg.calibration_memory, cfg.restart, cfg.block, cfg.hac_lags, 4 * n, cfg.window_blocks,
        ]
        wb = cfg.window_blocks
        per = spec.rows_per_sample
        self._arrays: dict[str, np.ndarray] = {
            "core_state": self.core._state,
            "gamma": np.zeros(cfg.hac_lags + 1),
            "mon": np.zeros(K.N_MON),
            "eff": np.zeros((G, K.N_EFF)),
            "on_before": np.zeros((G, qmax)),
            "on_se": np.zeros((G, qmax)),
            "sumA": np.zeros((G, qmax, qmax)),
            "sum_s": np.zeros((G, qmax)),
            "sumV": np.zeros((G, qmax, qmax)),
            "ring_X": np.zeros((max(wb, 1) if wb else 0, per * cfg.block, n)),
            "ring_y": np.zeros((max(wb, 1) if wb else 0, per * cfg.block)),
            "ring_n": np.zeros(2 + wb),
            "pending": np.zeros((0, _N_COLS)),
            # [samples seen, last t, dt (0: unknown), next status time]
            "stream": np.array([0.0, math.nan, 0.0, math.nan]),
        }
        eff = self._arrays["eff"]
        eff[:, K.E_Q] = self._q
        for g, q in enumerate(self._q):
            clip = stats.chi2.ppf(0.99, q)
            eff[g, K.E_CLIP] = clip
            # E[min(chi2_q, c)] = q F_{q+2}(c) + c (1 - F_q(c)): the winsorised mean under H0
            eff[g, K.E_CWIN] = q * stats.chi2.cdf(clip, q + 2) + clip * stats.chi2.sf(clip, q)
        self.events: list[dict] = []

    # ------------------------------------------------------------------ the stream
    def update(self, chunk: np.ndarray) -> list[dict]:
        """Feed samples; returns the events (and status lines) they raised.

        Ctrl-C (``KeyboardInterrupt``) between two steps leaves a consistent state: the
        samples of the steps done are processed (their events in :attr:`events`), the rest
        wait in the unprocessed buffer (saved with the state, processed first on resume).
        """
        data = self._validate(chunk)
        a = self._arrays
        stream = a["stream"]
        B = self.config.block
        with interrupts_held():  # the counters and the buffer of waiting samples change together
            if data.shape[0]:
                t_all = data[:2, 0] if math.isnan(stream[1]) else np.concatenate([[stream[1]], data[:1, 0]])
                if stream[2] == 0.0 and t_all.size > 1:
                    stream[2] = t_all[1] - t_all[0]
                stream[0] += data.shape[0]
                stream[1] = data[-1, 0]
                if math.isnan(stream[3]) and self.config.status_every:
                    stream[3] = data[0, 0] + self.config.status_every
            buf = np.concatenate([a["pending"], data]) if a["pending"].shape[0] else data
            a["pending"] = buf  # every sample received is processed or waiting, at any moment
        nb = buf.shape[0] // B
        out: list[dict] = []
        start = 0
        try:
            while start < nb:
                # a step: the blocks up to the next status line, processed whole (see above)
                with interrupts_held():
                    stop = nb
                    every = self.config.status_every
                    if every:
                        # cut at the block that reaches the next status time
                        ends = buf[np.arange(start, nb) * B + B - 1, 0]
                        hit = np.flatnonzero(ends >= stream[3])
                        if hit.size:
                            stop = start + int(hit[0]) + 1
                    out.extend(self._process(buf[start * B : stop * B]))
                    if every and buf[stop * B - 1, 0] >= stream[3]:
                        out.append(self.status())
                        stream[3] += every * max(1.0, math.floor((buf[stop * B - 1, 0] - stream[3]) / every) + 1.0)
                    start = stop
                    a["pending"] = buf[start * B :]  # a view: the copy is made once, below
        finally:  # the samples not processed (an incomplete block, or all after an interrupt) wait
            a["pending"] = np.array(buf[start * B :], dtype=float)
        return out

    def _validate(self, chunk: np.ndarray) -> np.ndarray:
        data = np.asarray(chunk, dtype=float)
        if data.ndim != 2 or data.shape[1] != _N_COLS:
            raise MeasurementError(f"a chunk must have shape (samples, {_N_COLS}) with columns {COLUMNS}, "
                                   f"got {data.shape}; the monitor was not changed")
        stream = self._arrays["stream"]
        try:  # the readers' checks (rotor_env.measurements.files), rows counted in the chunk
            check_finite("the chunk", data, COLUMNS)
            check_time("the chunk", data[:, 0], step=stream[2] or None, previous=stream[1])
        except MeasurementError as exc:
            raise MeasurementError(f"{exc}; the monitor was not changed") from None
        return data

    def _process(self, data: np.ndarray) -> list[dict]:
        if not data.shape[0]:
            return []
        a = self._arrays
        X, y = build_rows(self.core.spec, np.ascontiguousarray(data), self.core.ip)
        est = self.core.estimator
        events = np.zeros((data.shape[0] // self.config.block,
                           K.N_EV_FIXED + 4 * self._cols.shape[1] + K.isolation_width(*self._cols.shape)))
        n_ev = K.process_blocks(
            data, X, y, self.core.spec.rows_per_sample, est.R, est._col_sq, est._sums, self.core._masks,
            self._cols, self._scales, self._cfg, a["gamma"], a["mon"], a["eff"], a["on_before"], a["on_se"],
            a["sumA"], a["sum_s"], a["sumV"], events, a["ring_X"], a["ring_y"], a["ring_n"])
        out = [self._event(row) for row in events[:n_ev]]
        self.events.extend(out)
        return out

    def _physical(self, g: int, coef: np.ndarray) -> dict[str, float]:
        name = self.effects[g]
        eff = EFFECTS[name]
        full = np.zeros(len(eff.coefficients))
        names = self.core.spec.groups[name]
        for c, v in zip(names, coef, strict=True):
            full[eff.coefficients.index(c)] = v
        return {k: float(v) for k, v in eff.from_coefficients(full).items()}

    def _isolation(self, row: np.ndarray) -> tuple[list[int], dict[str, float]]:
        """The effects whose change alone explains the deciding block (module docstring of
        :mod:`rotor_env.monitor.detector`, *Isolation*): ``(candidates, score per effect)``,
        best first; no candidates where the block alone decides nothing."""
        G, qm = self._cols.shape
        o = K.N_EV_FIXED + 4 * qm
        # the energy each explains, in the noise's variance: less what noise alone would
        score = np.array([row[o + h * (1 + 4 * qm)] for h in range(G)]) - self._q
        scores = {e: float(v) for e, v in zip(self.effects, score, strict=True) if np.isfinite(v)}
        if not scores:
            return [], scores
        best = int(np.nanargmax(score))
        if not score[best] > stats.chi2.ppf(1.0 - ISOLATION_ALPHA, self._q[best]):
            return [], scores  # the change built up over blocks: the CUSUM's own attribution stands
        near = [h for h in range(G) if np.isfinite(score[h])
                and score[h] >= score[best] - stats.chi2.ppf(1.0 - ISOLATION_ALPHA, self._q[best] + self._q[h])]
        return sorted(near, key=lambda h: -score[h]), scores

    def _kind(self, g: int, before: np.ndarray, se_before: np.ndarray, after: np.ndarray,
              se_after: np.ndarray) -> str:
        # before: present when its coefficients differ from 0 by more than 3 standard
        # errors; a change from nothing is an appearance.  After: gone when within 3
        # standard errors of 0 or below 5 % of the size its plausible bounds allow (what
        # the errors in the regressors can leave behind is not an effect)
        relevant = 0.05 * self._scales[g]
        if not np.any(np.abs(before) > 3.0 * se_before):
            return "appeared"
        if not np.any(np.abs(after) > np.maximum(3.0 * se_after, relevant)):
            return "disappeared"
        return "changed"

    def _event(self, row: np.ndarray) -> dict:
        g = int(row[K.V_G])
        qm = self._cols.shape[1]
        o = K.N_EV_FIXED
        candidates, scores = self._isolation(row)
        q = int(self._q[g])
        onset = (row[o : o + q], row[o + qm : o + qm + q])
        sized = []  # (effect, before, its se, after, its se, the change's se)
        for h in candidates or [g]:
            qh = int(self._q[h])
            oh = o + 4 * qm + h * (1 + 4 * qm) + 1
            if candidates:
                # the effect's own change fitted to the deciding block, which lies wholly after
                # the change (the CUSUM's sums also hold the block that straddles it): the
                # value after is the reference there plus that change
                ref, se_ref = row[oh : oh + qh], row[oh + qm : oh + qm + qh]
                after = ref + row[oh + 2 * qm : oh + 2 * qm + qh]
                se_after = np.hypot(se_ref, row[oh + 3 * qm : oh + 3 * qm + qh])
                before, se_before = onset if h == g else (ref, se_ref)
                se_delta = se_after  # the reference's error there counts, as the block's
            else:  # the change built up over the CUSUM's blocks: its own sums
                before, se_before = onset
                after = before + row[o + 2 * qm : o + 2 * qm + q]
                se_delta = row[o + 3 * qm : o + 3 * qm + q]
                se_after = np.hypot(se_before, se_delta)
            sized.append((h, before, se_before, after, se_after, se_delta))
        found = []
        for h, before, se_before, after, se_after, se_delta in sized:
            delta = after - before
            name = self.effects[h]
            cols = self.core.spec.groups[name]
            found.append({
                "event": self._kind(h, before, se_before, after, se_after),
                "effect": name,
                "value_before": self._physical(h, before),
                "value_after": self._physical(h, after),
                "coefficients_before": dict(zip(cols, map(float, before), strict=True)),
                "change": dict(zip(cols, map(float, delta), strict=True)),
                "change_se": dict(zip(cols, map(float, se_delta), strict=True)),
                "orders": list(EFFECTS[name].orders),
                "signature": EFFECTS[name].signature,
            })
        evidence = {
            "cusum": float(row[K.V_S]),
            "threshold": float(self.threshold),
            "detected_by": self.effects[g],
            "blocks": int(row[K.V_BLOCKS]),
            "chi2": float(row[K.V_CHI]),
            "dof": int(row[K.V_DOF]),
            "log10_p": float(chi2_log10_sf(float(row[K.V_CHI]), int(row[K.V_DOF]))),
            "calibration": float(row[K.V_KAPPA]),
            "isolation": scores,
            "speed_onset": float(row[K.V_SPEED_ONSET]),
            "speed_alarm": float(row[K.V_SPEED]),
        }
        times = {"t_alarm": float(row[K.V_T]), "t_onset": float(row[K.V_T_ONSET])}
        if len(found) > 1:
            # the data of the block cannot tell these apart (a crack's step on a synchronous
            # orbit is a 1X forcing, as an unbalance's): say so, name none
            return {"event": "unattributed", "effect": None, **times, "candidates": [f["effect"] for f in found],
                    "value_before": {f["effect"]: f["value_before"] for f in found},
                    "value_after": {f["effect"]: f["value_after"] for f in found},
                    "evidence": {**evidence, "candidates": found}}
        f = found[0]
        evidence.update({k: f[k] for k in ("coefficients_before", "change", "change_se", "orders", "signature")})
        return {"event": f["event"], "effect": f["effect"], **times, "value_before": f["value_before"],
                "value_after": f["value_after"], "evidence": evidence}

    # ------------------------------------------------------------------ state
    @property
    def samples(self) -> int:
        """Samples received (processed or waiting in the last incomplete block)."""
        return int(self._arrays["stream"][0])

    @property
    def t(self) -> float:
        return float(self._arrays["mon"][K.M_LAST_T])

    @property
    def speed(self) -> float:
        return float(self._arrays["mon"][K.M_LAST_SPEED])

    @property
    def noise_floor(self) -> float:
        """Standard deviation of the equation error per row (pooled over the blocks so far)."""
        return float(math.sqrt(max(self._arrays["gamma"][0], 0.0)))

    @property
    def cusum(self) -> dict[str, float]:
        return {e: float(s) for e, s in zip(self.effects, self._arrays["eff"][:, K.E_S], strict=True)}

    @property
    def calibration(self) -> dict[str, float]:
        return {e: float(max(1.0, s)) for e, s in zip(self.effects, self._arrays["eff"][:, K.E_KAPPA], strict=True)}

    @property
    def counted_blocks(self) -> dict[str, int]:
        """Blocks that counted as evidence per effect (identifiable, calibrated)."""
        return {e: int(s) for e, s in zip(self.effects, self._arrays["eff"][:, K.E_COUNTED], strict=True)}

    def coefficients(self) -> dict[str, dict[str, float]]:
        """The reference model's physical parameters per effect."""
        coef, _, _ = self.core.significance()
        out = {}
        for g, name in enumerate(self.effects):
            out[name] = self._physical(g, coef[self._cols[g, : self._q[g]]])
        return out

    def significant(self) -> dict[str, bool]:
        """Each effect's partial F-test (tested last) on the reference window, ``p < 0.05``."""
        _, _, sig = self.core.significance()
        return {e: bool(s) for e, s in zip(self.effects, sig, strict=True)}

    @property
    def blocks(self) -> int:
        """Blocks processed."""
        return int(self._arrays["mon"][K.M_BLOCKS])

    @property
    def informative_blocks(self) -> int:
        """Blocks that carried evidence: enough rows where the disk moves relative to the shaft
        beyond the rates' noise (a dry-friction contact may stick it below: such rows say
        nothing of any effect), and a residual with degrees of freedom left."""
        return int(self._arrays["mon"][K.M_GAMMA_N])

    @property
    def blind(self) -> str:
        """Why the monitor sees nothing (``""`` where it sees): fewer than :data:`BLIND_SHARE`
        of the blocks carried evidence once :attr:`MonitorConfig.calibration_blocks` have
        passed.  Then the reference model stays at zero and no CUSUM runs -- not "nothing
        changed" but "nothing can be told".  The usual cause is a rig's probe noise: the
        equation error needs the rates and accelerations of the displacements, and their noise
        swamps the relative speed of a synchronous whirl, which turns with the shaft (a
        simulated healthy one-plane rig at 0.5 um: no block of 285 counted, and with the gate
        off the identification read an asymmetry D = 9.5 and a negative damping)."""
        n = self.blocks
        if n < self.config.calibration_blocks or self.informative_blocks >= BLIND_SHARE * n:
            return ""
        mon = self._arrays["mon"]
        sig_w, sig_th = math.sqrt(max(mon[K.M_SIG_W2], 0.0)), math.sqrt(max(mon[K.M_SIG_TH2], 0.0))
        return (f"blind: {self.informative_blocks} of {n} blocks carried evidence; in the others the disk's speed "
                f"relative to the shaft stayed within {self.config.stick_sigmas:g} times the noise of the rates "
                f"(rate noise {sig_w:.3g}, inclination noise {sig_th:.3g} per sample, model units), where the "
                "equation error cannot weigh any effect -- its rates and accelerations are estimated from the "
                "displacements, and at this noise they are noise. Nothing is identified and no alarm can be "
                "raised: this is not a healthy verdict. Diagnose a recorded run where it was measured: "
                "rotor-id diagnose RUN --rig RIG.yaml (the output-error fit of the probes' displacements)")

    def status(self) -> dict:
        out = {"event": "status", "t": self.t, "speed": self.speed, "coefficients": self.coefficients(),
               "significant": self.significant(), "noise_floor": self.noise_floor, "cusum": self.cusum}
        blind = self.blind
        if blind:
            out["blind"] = blind
        return out

    def summary(self) -> dict:
        """The end-of-stream summary: ``t`` the last processed sample's time, ``t_received`` the
        last received one's; ``unprocessed_samples`` between them wait (the last incomplete
        block, or all after Ctrl-C stopped a step) and are saved with the state."""
        received = float(self._arrays["stream"][1])
        return {"event": "summary", "samples": self.samples, "t": self.t, "speed": self.speed,
                "t_received": received if math.isfinite(received) else None,
                "alarms": len(self.events),
                "events": [{k: e[k] for k in ("event", "effect", "candidates", "t_onset", "t_alarm") if k in e}
                           for e in self.events],
                "coefficients": self.coefficients(), "significant": self.significant(),
                "noise_floor": self.noise_floor, "counted_blocks": self.counted_blocks,
                "blocks": self.blocks, "informative_blocks": self.informative_blocks, "blind": self.blind,
                "threshold": self.threshold, "arl0": self.config.arl0,
                "unprocessed_samples": int(self._arrays["pending"].shape[0])}

    # ------------------------------------------------------------------ save / restore
    def save(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write the complete state to ``.npz`` (no pickle); refuses to overwrite by default."""
        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"state files end in .npz, got {str(path)!r}")
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
        meta = {"version": _STATE_VERSION, "config": asdict(self.config), "events": self.events}

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.savez(fh, meta=np.array(json.dumps(meta)), **self._arrays)

        # refused above unless overwrite: the write itself replaces
        return atomic_write(path, write, overwrite=True)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Monitor:
        """Restore a state written by :meth:`save`; continuing equals an uninterrupted run."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as npz:
                meta = json.loads(str(npz["meta"]))
                arrays = {k: np.array(npz[k]) for k in npz.files if k != "meta"}
        except Exception as exc:  # a truncated or altered file: zip, zlib or format errors of any kind
            raise ValueError(f"{path}: not a monitor state file ({type(exc).__name__}: {str(exc)[:200]})") from None
        if not isinstance(meta, dict) or meta.get("version") != _STATE_VERSION:
            raise ValueError(f"{path}: unsupported monitor state version")
        known = {f.name for f in fields(MonitorConfig)}
        config = {k: v for k, v in meta.get("config", {}).items() if k in known}
        config["effects"] = tuple(config.get("effects", DEFAULT_EFFECTS))
        try:
            mon = cls(MonitorConfig(**config))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: the monitor state's configuration is not valid ({str(exc)[:200]})") from None
        for name, ref in mon._arrays.items():
            got = arrays.get(name)
            if got is None or (name != "pending" and got.shape != ref.shape) or got.dtype.kind != "f":
                raise ValueError(f"{path}: array {name!r} is missing or does not match the configuration")
            if name not in ("stream",) and not np.isfinite(got).all():
                raise ValueError(f"{path}: array {name!r} holds non-finite values")
        for name, ref in mon._arrays.items():
            if name == "pending":
                if arrays[name].ndim != 2 or arrays[name].shape[1] != _N_COLS:
                    raise ValueError(f"{path}: array 'pending' does not have {_N_COLS} columns")
                mon._arrays[name] = arrays[name].astype(float)
            else:
                ref[...] = arrays[name]  # in place: the core's estimator holds views of core_state
        mon.events = list(meta.get("events", []))
        return mon
