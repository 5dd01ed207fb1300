"""The figures of a diagnosis: what each one draws, computed from the diagnosis's fields.

:class:`DiagnosisFigures` is a mixin of :class:`~rotor_env.diagnosis.result.Diagnosis`:
its ``plot_*`` methods compute what a figure shows (the residual's order map, the 1X
vectors, the whirl model, the parameter tracks, each in the units of :meth:`plot_units`)
and hand the numbers to the drawing in :mod:`rotor_env.plots` (``plots.diagnosis`` for
the diagnosis's own figures, ``plots.field`` for Bode, polar, orbits, waterfall, Campbell
and tracks).  The HTML page that embeds them is :mod:`.report`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from .. import plots
from ..effects import whirl_effects
from ..measurements.vectors import order_map
from ..outputs import atomic_write
from ..plots import diagnosis as draw
from . import field
from .orders import autocorrelation, complex_rows, failing_windows, first_rows

__all__ = ["DiagnosisFigures", "PlotUnits"]


@dataclass(frozen=True)
class PlotUnits:
    """How a diagnosis's (dimensionless) samples are drawn.

    ``t_plot = t * time_factor``; a rate ``w`` (rad per model time unit) is
    ``w * rate_factor`` rad per plotted time unit, shown in ``speed_unit`` (see
    :mod:`rotor_env.plots.field`).  Without a known time unit everything stays dimensionless.
    """

    time_factor: float = 1.0
    rate_factor: float = 1.0
    time_unit: str = "dimensionless"
    speed_unit: str = "dimensionless"
    amp_unit: str = "rad"

    def time(self, t):
        return np.asarray(t, dtype=float) * self.time_factor

    def speed(self, w):
        """A spin speed (rad per model time unit) in :attr:`speed_unit`."""
        return plots.speed_from_rad(np.asarray(w, dtype=float) * self.rate_factor, self.speed_unit)

    def frequency(self, w):
        """A whirl frequency (rad per model time unit) in the Campbell/waterfall unit."""
        return plots.frequency_from_rad(np.asarray(w, dtype=float) * self.rate_factor, self.speed_unit)

    def label(self, quantity: str, unit: str | None = None) -> str:
        unit = unit or "dimensionless"
        return f"{quantity} ({unit})"


class DiagnosisFigures:
    """The figures of :class:`~rotor_env.diagnosis.Diagnosis` (a mixin: reads its fields)."""

    # -------------------------------------------------------------- units
    def plot_units(self) -> PlotUnits:
        """The units the figures use: the model's dimensionless ones, or seconds and rpm
        where the diagnosis knows its file's time unit (``time_unit == "s"``) and scale
        (``time_scale``: ``t_model = time_scale * t_file``)."""
        scale = float(getattr(self, "time_scale", 1.0) or 1.0)
        unit = getattr(self, "time_unit", None)
        amp = getattr(self, "amplitude_unit", None) or "rad"
        if unit == "s":
            return PlotUnits(time_factor=1.0 / scale, rate_factor=scale, time_unit="s", speed_unit="rpm",
                             amp_unit=amp)
        return PlotUnits(amp_unit=amp)

    def _field_cache(self) -> dict:
        """Per-revolution vectors etc., computed once per diagnosis (figures share them)."""
        cache = self.__dict__.get("_field_plot_cache")
        if cache is None:
            cache = self.__dict__["_field_plot_cache"] = {}
        return cache

    def _critical_window(self) -> tuple[float, float]:
        """The speed range around the measured 1x peak (the critical): where the zooms look."""
        m = self.data.meas
        amp = np.hypot(m.theta_x, m.theta_y)
        w_peak = float(m.phi_dot[int(np.argmax(amp))])
        lo, hi = float(np.min(m.phi_dot)), float(np.max(m.phi_dot))
        half = max(0.15 * abs(w_peak), 0.03 * (hi - lo))
        return max(lo, w_peak - half), min(hi, w_peak + half)

    # -------------------------------------------------------------- compare
    # -------------------------------------------------------------- compare
    def plot_compare(self, ax=None, which: str = "after", zoom: bool = True):
        """Measured vs model amplitude ``|theta|`` against speed (free-run simulation),
        with a zoom on the critical; without ``ax`` (or with a pair of axes) a second
        panel shows the output error ``|theta_measured - theta_model|`` of the starting
        and the final model, so the change is seen where it happens."""
        u = self.plot_units()
        m = self.data.meas
        comps = [(self.before, "starting model")]
        if which in ("after", "both"):
            comps.append((self.after, "final model"))
        models, errors = {}, {}
        for comp, label in comps:
            if comp.simulated is not None:
                sim = comp.simulated
                models[f"{label}: {', '.join(comp.model)} (fit {comp.fit_percent:.0f} %)"] = (
                    u.speed(sim.phi_dot), np.hypot(sim.theta_x, sim.theta_y))
                errors[label] = np.hypot(m.theta_x - sim.theta_x, m.theta_y - sim.theta_y)
        return draw.plot_compare(u.speed(m.phi_dot), np.hypot(m.theta_x, m.theta_y), models, errors=errors,
                                 zoom=tuple(float(v) for v in u.speed(np.array(self._critical_window())))
                                 if zoom else None,
                                 speed_unit=u.speed_unit, amp_unit=u.amp_unit, ax=ax)

    def plot_residual(self, ax=None, which: str = "before"):
        """Equation-error residual against time, speed on a top axis (exact: piecewise
        linear through the samples, extrapolated linearly past the ends); shaded where
        its rolling RMS stands above 2x the noise floor."""
        u = self.plot_units()
        comp = self.before if which == "before" else self.after
        m = self.data.meas
        if which == "before":
            windows = self.windows
        else:  # where the final model still fails (against the same floor)
            windows, _ = failing_windows(m.t, first_rows(comp.residual, self.equation), floor=self.noise_floor)
        return draw.plot_residual(np.repeat(u.time(m.t), 2 if self.equation == "both" else 1), comp.residual,
                                  self.noise_floor,
                                  windows=[(w["t_start"] * u.time_factor, w["t_end"] * u.time_factor) for w in windows],
                                  speed_axis=(u.time(m.t), u.speed(m.phi_dot)), which=which, model=comp.model,
                                  rms=comp.rms, time_unit=u.time_unit, speed_unit=u.speed_unit, ax=ax)

    def plot_order_map(self, ax=None, which: str = "before", lookalikes: int = 2):
        """Residual spectrum in rotation orders against speed, 0x/1x/2x marked.

        Each added effect's declared (signed) orders are drawn as solid vertical lines
        labelled with its name in the legend; the orders of up to ``lookalikes`` of its
        lookalikes (those not added themselves) dashed.  An effect that declares no
        order line gets a legend entry saying so.
        """
        comp = self.before if which == "before" else self.after
        m = self.data.meas
        u = self.plot_units()
        speeds, orders, amp = order_map(m.t, m.phi, u.speed(m.phi_dot), complex_rows(comp.residual, self.equation))
        mirrored = [(name, k, u.speed(speed), order) for name, k, speed, order in self._mirrored_whirl()]
        return draw.plot_order_map(speeds, orders, amp, expected=self._expected_lines(lookalikes), mirrored=mirrored,
                                   which=which, speed_unit=u.speed_unit, ax=ax)

    #: effects whose moment mirrors a whirl ``z ~ e^{i w t}`` into ``e^{i (m Omega - w) t}``
    #: (``conj(z) e^{i m phi}``): a rotating asymmetry (m = 2); its residual sits there, not at
    #: its declared 1x/2x, when the record holds free whirl (the crack's opening excites it);
    #: Gasch's hinge too (``max(xi, 0) n`` holds ``xi n / 2 = (z + conj(z) n^2) / 4``)
    MIRRORING: ClassVar[dict[str, int]] = {"asymmetry": 2, "breathing_crack": 2, "hinge_crack": 2}

    def _mirrored_whirl(self) -> list[tuple[str, int, np.ndarray, np.ndarray]]:
        """``(effect, m, speed, order)`` of each added mirroring effect: the order
        ``m - w_f / Omega`` of the final model's forward free whirl ``w_f`` against speed."""
        added = [(e, self.MIRRORING[e]) for e in self.missing if e in self.MIRRORING]
        if not added:
            return []
        speed, branches = self.whirl_model()
        forward = [np.asarray(w, float) for w in branches.values() if np.nanmedian(np.asarray(w, float)) > 0]
        if not forward:
            return []
        w_f = min(forward, key=lambda w: float(np.nanmedian(w)))  # the lowest forward branch
        keep = speed > 0.3 * float(np.nanmax(speed))  # Omega -> 0: the mirror runs off the map
        return [(e, m, speed[keep], m - w_f[keep] / speed[keep]) for e, m in added]

    def _expected_lines(self, lookalikes: int = 2) -> list[tuple[str, tuple[float, ...], str]]:
        """``(effect, signed orders, "added" | "lookalike")`` for each added effect and up to
        ``lookalikes`` of its lookalikes per effect (each effect once; the added first)."""
        evidence = {ev.get("effect"): ev for ev in (getattr(self, "lookalikes", None) or [])}
        out, seen = [], set()
        for name in self.missing:
            ev = evidence.get(name) or {}
            declared = ev.get("declared_orders")
            out.append((name, tuple(_declared_orders(name) if declared is None else declared), "added"))
            seen.add(name)
        for name in self.missing:
            ev = evidence.get(name) or {}
            shown = 0
            for lk in ev.get("lookalikes") or []:
                other = lk.get("effect")
                if shown >= lookalikes or other in seen:
                    continue
                declared = lk.get("declared_orders")
                out.append((other, tuple(_declared_orders(other) if declared is None else declared), "lookalike"))
                seen.add(other)
                shown += 1
        return out


    def plot_autocorrelation(self, ax=None, which: str = "before", max_lag: int = 400):
        """Residual autocorrelation with 95 % bounds for white noise."""
        comp = self.before if which == "before" else self.after
        r = first_rows(comp.residual, self.equation)
        ac = autocorrelation(r, max_lag)
        u = self.plot_units()
        lags = np.arange(len(ac)) * self.data.meas.dt * u.time_factor
        return draw.plot_autocorrelation(lags, ac, 1.96 / math.sqrt(len(r)), which=which, time_unit=u.time_unit,
                                         ax=ax)

    def plot_candidates(self, ax=None):
        """The ranking: -log10 p of adding each candidate, with the Bonferroni line."""
        c = self.candidates
        return draw.plot_candidates([x.effect for x in c], [x.log10_p for x in c], [x.effect in self.missing for x in c],
                                    -math.log10(self.alpha / max(1, len(c))), ax=ax)

    def plot_before_after(self, ax=None, zoom: bool = True):
        """Equation-error RMS and free-run fit % along the forward selection; without
        ``ax`` (or with a pair of axes) also the residual of the starting and the final
        model over time, zoomed where the starting model failed most."""
        u = self.plot_units()
        steps = [self.before, *self.steps]
        residuals = {"t": u.time(self.data.meas.t), "before": first_rows(self.before.residual, self.equation),
                     "after": first_rows(self.after.residual, self.equation), "rms_before": self.before.rms,
                     "rms_after": self.after.rms, "noise_floor": self.noise_floor, "time_unit": u.time_unit}
        return draw.plot_before_after(["start"] + [f"+ {e}" for e in self.missing], [s.fit_percent for s in steps],
                                      [s.rms for s in steps], residuals=residuals, zoom=zoom, ax=ax)

    # -------------------------------------------------------------- field views
    def _vectors(self) -> dict:
        """1X vectors per revolution (lead convention) of the measured angles and of the
        starting and final models' free runs: ``{"t", "speed", "measured", "models"}``."""
        cache = self._field_cache()
        if "vectors" not in cache:
            m = self.data.meas
            channels = {"θy (horizontal)": "theta_y", "θx (vertical)": "theta_x"}

            def one(rec):
                out, t_mid, speed = {}, None, None
                for label, col in channels.items():
                    t_mid, speed, v = field.order_vectors(rec.t, rec[col], rec.phi)
                    out[label] = v[1]
                return t_mid, speed, out

            t_mid, speed, measured = one(m)
            models = {}
            for comp, name in ((self.before, "starting model"), (self.after, "final model")):
                if comp.simulated is not None and len(comp.simulated) == len(m):
                    models[name] = one(comp.simulated)[2]
            cache["vectors"] = {"t": t_mid, "speed": speed, "measured": measured, "models": models}
        return cache["vectors"]

    def plot_bode(self, ax=None, phase: str = "lag"):
        """Bode plot of the 1X vectors of ``theta_y`` (horizontal) and ``theta_x`` (vertical):
        measured, starting and final model (free runs); ``ax``: a pair of axes."""
        u = self.plot_units()
        v = self._vectors()
        return plots.plot_bode(u.speed(v["speed"]), v["measured"], v["models"], speed_unit=u.speed_unit,
                            amp_unit=u.amp_unit, phase=phase, ax=ax)

    def plot_polar(self, ax=None, phase: str = "lag"):
        """Polar (Nyquist) plot of the same 1X vectors, speeds written along the curves."""
        u = self.plot_units()
        v = self._vectors()
        return plots.plot_polar(u.speed(v["speed"]), v["measured"], v["models"], speed_unit=u.speed_unit,
                             amp_unit=u.amp_unit, phase=phase, ax=ax)

    def orbit_times(self) -> list[float]:
        """Three moments for orbits (model time): below, at and above the critical (the
        revolution of the largest measured 1X vector)."""
        v = self._vectors()
        t, speed = v["t"], v["speed"]
        if t is None or len(t) == 0:
            return []
        amp = np.hypot(*(np.nan_to_num(np.abs(x)) for x in v["measured"].values()))
        j = int(np.argmax(amp))
        out = []
        for target in (0.75 * speed[j], None, 1.3 * speed[j]):
            k = j if target is None else int(np.nanargmin(np.abs(speed - target)))
            out.append(float(t[k]))
        return sorted(set(out))

    def plot_orbit(self, ax=None, at_times=None, filtered: bool = True):
        """Orbits ``theta_x`` (vertical) against ``theta_y`` (horizontal), unfiltered and
        1X-filtered with the keyphasor dot, at ``at_times`` (model time; default: below, at
        and above the critical)."""
        u = self.plot_units()
        m = self.data.raw
        times = self.orbit_times() if at_times is None else list(np.atleast_1d(at_times))
        return plots.plot_orbit(u.time(m.t), m.theta_y, m.theta_x, m.phi, [u.time(x) for x in times],
                             filtered=filtered, unit=u.amp_unit, speed_unit=u.speed_unit, time_unit=u.time_unit,
                             labels=("θy (horizontal)", "θx (vertical)"), ax=ax)

    def plot_waterfall(self, ax=None, x_axis: str = "frequency"):
        """Waterfall of the measured ``z = theta_y + i theta_x`` (unfiltered): spectra of
        8-revolution blocks against speed, signed (forward/backward whirl), 1x/2x lines."""
        u = self.plot_units()
        m = self.data.raw
        return plots.plot_waterfall(u.time(m.t), m.theta_y + 1j * m.theta_x, m.phi, x_axis=x_axis,
                                 speed_unit=u.speed_unit, amp_unit=u.amp_unit, ax=ax)

    def whirl_model(self, n: int = 200) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """``(speed, {branch: signed frequency})`` of the final model's linear fixed-frame part
        (stiffness, damping, ``ip``, support anisotropy, cross-coupling) over the measured
        speed range, in model units (:func:`.field.whirl_frequencies`)."""
        phys = self.after.physical
        top = float(np.max(np.abs(self.data.meas.phi_dot)))
        speed = np.linspace(0.0, top, n)
        return speed, field.whirl_frequencies(speed, phys.get("k", 1.0), phys.get("c", 0.0), self.ip,
                                           phys.get("support_anisotropy", 0.0), phys.get("cross_coupling", 0.0))

    def plot_campbell(self, ax=None):
        """Campbell diagram of the final model (forward and backward whirl against speed,
        1x and 2x lines, criticals where 1x crosses a branch) with the whirl peaks found in
        the measured waterfall."""
        u = self.plot_units()
        speed, branches = self.whirl_model()
        m = self.data.raw
        ps, pw = field.whirl_peaks(m.t, m.theta_y + 1j * m.theta_x, m.phi)
        fig = plots.plot_campbell(u.speed(speed), {k: u.frequency(w) for k, w in branches.items()},
                               measured_peaks=(u.speed(ps), u.frequency(pw)) if len(ps) else None,
                               speed_unit=u.speed_unit, ax=ax)
        covered = [e for e in whirl_effects() if e in self.model]
        _first_axes(fig, ax).set_title(
            "Campbell diagram of the final model (linear fixed-frame part: ip"
            + (", " + ", ".join(covered) if covered else "") + ")", fontsize=9)
        return fig

    def parameter_tracks(self, forgetting: float | None = None) -> field.ParameterTracks:
        """The recursive identifier run over the (prefiltered) data with the final model's
        effects: coefficients after every sample and per-effect significance.  Default
        ``forgetting``: a memory of a tenth of the record (at least 2000 rows)."""
        cache = self._field_cache()
        key = ("tracks", forgetting)
        if key not in cache:
            rows = len(self.data.meas) * (2 if self.equation == "both" else 1)
            lam = forgetting if forgetting is not None else 1.0 - 1.0 / max(2000.0, rows / 10.0)
            cache[key] = field.parameter_tracks(self.data.meas, self.model, self.ip, lam, alpha=self.alpha,
                                             equation=self.equation)
        return cache[key]

    def monitor_alarms(self) -> list[dict] | None:
        """The on-line monitor's calibrated alarms over the record with the final model's
        effects (:func:`.field.monitor_alarms`; model time), None where the monitor
        cannot watch this model (an effect with a scanned parameter)."""
        cache = self._field_cache()
        if "alarms" not in cache:
            try:
                cache["alarms"] = field.monitor_alarms(self.data.meas, self.model, self.ip)
            except (ValueError, KeyError, NotImplementedError):
                cache["alarms"] = None
        return cache["alarms"]

    def plot_parameter_tracks(self, ax=None, truth: dict[str, float] | None = None,
                              forgetting: float | None = None):
        """Parameter tracks of the online identification, with the on-line monitor's
        calibrated alarms (the bottom panel: an effect from the onset of its change on);
        the batch estimates of the diagnosis (95 % HAC) at the right end; ``truth``
        (coefficient name -> value, or an array over the record; default: :attr:`truth`)
        dashed for simulated data."""
        u = self.plot_units()
        tr = self.parameter_tracks(forgetting)
        final = {c: (float(v), 1.96 * float(s)) for c, v, s in
                 zip(self.after.columns, self.after.coefficients, self.after.standard_errors, strict=True)
                 if c in tr.coefficients}
        truth = truth if truth is not None else getattr(self, "truth", None)
        alarms = self.monitor_alarms()
        if alarms is not None:
            alarms = [{**a, "t_onset": float(u.time(a["t_onset"])), "t_alarm": float(u.time(a["t_alarm"]))}
                      for a in alarms]
            fig = plots.plot_parameter_tracks(u.time(tr.t), tr.coefficients, alarms=alarms, truth=truth,
                                           groups=tr.groups, final=final, time_unit=u.time_unit, ax=ax)
            marks = "dotted: onset of an alarm of the monitor's calibrated test"
        else:  # the identifier's own flags (white-residual F tests), said so
            fig = plots.plot_parameter_tracks(u.time(tr.t), tr.coefficients, significance=tr.significant,
                                           truth=truth, groups=tr.groups, final=final, time_unit=u.time_unit, ax=ax)
            marks = "bold where the effect-last F test (white residual) is significant"
        _first_axes(fig, ax).set_title(
            f"online identification (recursive QR, forgetting {tr.forgetting:.5g}): {marks}; "
            + ("dashed: truth; " if truth else "") + "squares: batch estimate ± 95 %", fontsize=8)
        return fig

    #: the figures :meth:`figures` draws, by file name
    FIGURES = ("compare", "residual", "order_map", "autocorrelation", "candidates", "before_after",
               "residual_after", "bode", "polar", "orbit", "waterfall", "campbell", "parameter_tracks")

    def figures(self) -> dict[str, object]:
        return {
            "compare": self.plot_compare(which="both"),
            "residual": self.plot_residual(),
            "order_map": self.plot_order_map(),
            "autocorrelation": self.plot_autocorrelation(),
            "candidates": self.plot_candidates(),
            "before_after": self.plot_before_after(),
            "residual_after": self.plot_residual(which="after"),
            "bode": self.plot_bode(),
            "polar": self.plot_polar(),
            "orbit": self.plot_orbit(),
            "waterfall": self.plot_waterfall(),
            "campbell": self.plot_campbell(),
            "parameter_tracks": self.plot_parameter_tracks(),
        }

    def save_figures(self, folder: str | Path, *, overwrite: bool = True) -> list[Path]:
        """Every figure as ``folder/<name>.png`` (each written atomically)."""
        import matplotlib.pyplot as plt

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, fig in self.figures().items():
            paths.append(atomic_write(
                folder / f"{name}.png",
                lambda p, fig=fig: fig.savefig(p, format="png", dpi=110, bbox_inches="tight"),
                overwrite=overwrite,
            ))
            plt.close(fig)
        return paths


def _first_axes(fig, ax):
    """The axes a plot drew first on: the caller's (one, or the first of several) or the
    new figure's first."""
    if ax is None:
        return fig.axes[0]
    return ax[0] if isinstance(ax, (list, tuple, np.ndarray)) else ax


def _declared_orders(name) -> tuple:
    """The signed rotation orders the library declares for effect ``name`` (``()`` if unknown)."""
    from ..effects import EFFECTS

    eff = EFFECTS.get(name)
    return tuple(getattr(eff, "orders", ()) or ()) if eff is not None else ()

