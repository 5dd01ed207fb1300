"""Figures and the self-contained HTML report of a diagnosis."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from .. import plots
from ..effects import whirl_effects
from ..measurements.vectors import order_map
from ..outputs import atomic_write, check_writable
from ..pages import esc, figure_tag, write_page
from . import field
from .orders import autocorrelation, complex_rows, failing_windows, first_rows
from .verdict import VERDICT_TEXT

#: the diagnosis page's own rules: the verdict's box and colours, the missing effects' rows
_STYLE = ("td,th{font-size:13px}tr.missing{background:#fde0dc}"
          "section.verdict{border:2px solid #888;border-radius:6px;padding:.3em 1em;margin:1em 0}"
          "p.verdict-word{font-size:2em;font-weight:bold;margin:.2em 0}"
          ".verdict-explained,.verdict-explained_after_adding{border-color:#2a8a3a!important}"
          ".verdict-partly_explained{border-color:#d98a00!important}"
          ".verdict-unexplained{border-color:#c0392b!important}"
          ".verdict-explained p.verdict-word,.verdict-explained_after_adding p.verdict-word{color:#2a8a3a}"
          ".verdict-partly_explained p.verdict-word{color:#d98a00}"
          ".verdict-unexplained p.verdict-word{color:#c0392b}")


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


def _interp_linear(x, xp: np.ndarray, fp_: np.ndarray):
    """``np.interp`` that extrapolates linearly past both ends (end slopes over up to 10
    samples) instead of clamping: a secondary axis built on it maps the whole axis range,
    margins included, one-to-one (a clamped map puts the ticks in the wrong place).
    ``xp`` must be increasing."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(np.interp(x, xp, fp_), dtype=float)
    k = min(len(xp) - 1, 10)
    if k < 1:
        return y
    lo, hi = x < xp[0], x > xp[-1]
    s_lo = (fp_[k] - fp_[0]) / (xp[k] - xp[0])
    s_hi = (fp_[-1] - fp_[-1 - k]) / (xp[-1] - xp[-1 - k])
    y = np.where(lo, fp_[0] + (x - xp[0]) * s_lo, y)
    return np.where(hi, fp_[-1] + (x - xp[-1]) * s_hi, y)


def speed_axis_functions(t: np.ndarray, speed: np.ndarray):
    """``(t -> speed, speed -> t)`` for ``secondary_xaxis`` where the speed is monotone in
    time (run-up or coast-down): piecewise linear through the samples, extrapolated
    linearly past the record's ends; ``None`` where the speed is not monotone."""
    t, speed = np.asarray(t, dtype=float), np.asarray(speed, dtype=float)
    d = np.diff(speed)
    if len(t) < 2 or not (np.all(d > 0) or np.all(d < 0)):
        return None
    if d[0] > 0:
        return (lambda x: _interp_linear(x, t, speed)), (lambda s: _interp_linear(s, speed, t))
    # a coast-down: the inverse interpolates on the speed reversed (np.interp needs it rising)
    return (lambda x: _interp_linear(x, t, speed)), (lambda s: _interp_linear(s, speed[::-1], t[::-1]))


class DiagnosisFigures:
    """The figures of :class:`~rotor_env.diagnosis.Diagnosis` (a mixin: reads its fields)."""

    def _ax(self, ax, figsize=(8, 4)):
        """``(figure, axes)``: the caller's ``ax`` or a new figure (matplotlib picks the
        backend: Agg on a machine without a display)."""
        if ax is None:
            import matplotlib.pyplot as plt

            fig, ax = plt.subplots(figsize=figsize)
            return fig, ax
        return ax.figure, ax

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
    def plot_compare(self, ax=None, which: str = "after", zoom: bool = True):
        """Measured vs model amplitude ``|theta|`` against speed (free-run simulation),
        with a zoom on the critical; without ``ax`` (or with a pair of axes) a second
        panel shows the output error ``|theta_measured - theta_model|`` of the starting
        and the final model, so the change is seen where it happens."""
        u = self.plot_units()
        if ax is None:
            import matplotlib.pyplot as plt

            fig, axes = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
        else:
            axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
            fig = axes[0].figure
        top = axes[0]
        m = self.data.meas
        speed = u.speed(m.phi_dot)
        curves = [(speed, np.hypot(m.theta_x, m.theta_y), {"color": "k", "lw": 1.2}, "measured")]
        comps = [(self.before, {"color": "C3", "ls": "--", "lw": 1.0}, "starting model")]
        if which in ("after", "both"):
            comps.append((self.after, {"color": "C0", "lw": 1.0}, "final model"))
        errors = []
        for comp, style, label in comps:
            if comp.simulated is not None:
                sim = comp.simulated
                curves.append((u.speed(sim.phi_dot), np.hypot(sim.theta_x, sim.theta_y), style,
                               f"{label}: {', '.join(comp.model)} (fit {comp.fit_percent:.0f} %)"))
                errors.append((np.hypot(m.theta_x - sim.theta_x, m.theta_y - sim.theta_y), style, label))
        for x, y, style, label in curves:
            top.plot(x, y, label=label, **style)
        top.set_ylabel(u.label(r"amplitude $|\theta|$", u.amp_unit))
        # above the axes, between them and the title: never over a curve (nor the zoom)
        top.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=2, frameon=False,
                   borderaxespad=0.0)
        top.set_title("measured vs model response (free run)", pad=8 + 11 * ((len(curves) + 1) // 2))
        lo, hi = (float(v) for v in u.speed(np.array(self._critical_window())))
        if zoom and hi > lo:
            inset = top.inset_axes([0.62, 0.45, 0.36, 0.5])
            for x, y, style, _ in curves:
                sel = (x >= lo) & (x <= hi)
                inset.plot(x[sel], y[sel], **style)
            inset.set_title("zoom: the critical", fontsize=7)
            inset.tick_params(labelsize=6)
            top.indicate_inset_zoom(inset, edgecolor="0.5")
        if len(axes) > 1:
            bottom = axes[1]
            for err, style, label in errors:
                bottom.plot(speed, err, label=f"{label} (RMS {np.sqrt(np.mean(err**2)):.3g})",
                            **{**style, "lw": 0.8})
            bottom.set_ylabel(u.label(r"output error $|\theta - \theta_{model}|$", u.amp_unit))
            bottom.legend(fontsize=7, loc="upper left")
            bottom.set_xlabel(u.label("spin speed", u.speed_unit))
        else:
            top.set_xlabel(u.label("spin speed", u.speed_unit))
        return fig

    def plot_residual(self, ax=None, which: str = "before"):
        """Equation-error residual against time, speed on a top axis (exact: piecewise
        linear through the samples, extrapolated linearly past the ends); shaded where
        its rolling RMS stands above 2x the noise floor."""
        fig, ax = self._ax(ax)
        u = self.plot_units()
        comp = self.before if which == "before" else self.after
        m = self.data.meas
        t = np.repeat(u.time(m.t), 2 if self.equation == "both" else 1)
        ax.plot(t, comp.residual, lw=0.3, color="C3" if which == "before" else "C0")
        if which == "before":
            windows = self.windows
        else:  # where the final model still fails (against the same floor)
            windows, _ = failing_windows(m.t, first_rows(comp.residual, self.equation), floor=self.noise_floor)
        for w in windows:
            ax.axvspan(w["t_start"] * u.time_factor, w["t_end"] * u.time_factor, color="orange", alpha=0.2)
        ax.axhline(2 * self.noise_floor, color="k", lw=0.5, ls=":")
        ax.axhline(-2 * self.noise_floor, color="k", lw=0.5, ls=":")
        ax.set_xlabel(u.label("t", u.time_unit))
        ax.set_ylabel("equation residual (dimensionless moment)")
        ax.set_title(f"residual of the {which} model ({', '.join(comp.model)}); RMS {comp.rms:.3g}; "
                     "shaded: above 2x the noise floor (dotted)", fontsize=9)
        funcs = speed_axis_functions(u.time(m.t), u.speed(m.phi_dot))
        if funcs is not None:  # a speed axis only where speed maps one-to-one onto time
            top = ax.secondary_xaxis("top", functions=funcs)
            top.set_xlabel(u.label("speed", u.speed_unit))
        return fig

    def plot_order_map(self, ax=None, which: str = "before", lookalikes: int = 2):
        """Residual spectrum in rotation orders against speed, 0x/1x/2x marked.

        Each added effect's declared (signed) orders are drawn as solid vertical lines
        labelled with its name in the legend; the orders of up to ``lookalikes`` of its
        lookalikes (those not added themselves) dashed.  An effect that declares no
        order line gets a legend entry saying so.
        """
        fig, ax = self._ax(ax)
        comp = self.before if which == "before" else self.after
        m = self.data.meas
        u = self.plot_units()
        speeds, orders, amp = order_map(m.t, m.phi, u.speed(m.phi_dot), complex_rows(comp.residual, self.equation))
        speeds, amp = plots.by_speed(speeds, amp)  # pcolormesh wants monotonic rows (else a UserWarning)
        if amp.size:
            mesh = ax.pcolormesh(orders, speeds, np.log10(amp + 1e-12), shading="nearest", cmap="viridis")
            fig.colorbar(mesh, ax=ax, label="log10 amplitude (dimensionless moment)")
        for o in (-2, -1, 0, 1, 2):
            ax.axvline(o, color="w", lw=0.6, ls=":")
            ax.text(o, speeds.max() if amp.size else 1, f"{o}x", color="k", ha="center", va="bottom", fontsize=8)
        lines = self._expected_lines(lookalikes)
        for i, (name, declared, kind) in enumerate(lines):
            colour = _LINE_COLOURS[i % len(_LINE_COLOURS)]
            style = ({"ls": "-", "lw": 1.6, "alpha": 0.95} if kind == "added"
                     else {"ls": "--", "lw": 1.1, "alpha": 0.85})
            label = name if kind == "added" else f"{name} (lookalike)"
            if not declared:  # no order line: said in the legend, nothing drawn on the map
                ax.plot([], [], color=colour, label=f"{label}: no order line", **style)
                continue
            for j, o in enumerate(declared):
                ax.axvline(o, color=colour, label=label if j == 0 else None, **style)
        mirrored = self._mirrored_whirl()
        for i, (name, m, speed_model, order) in enumerate(mirrored):
            ax.plot(order, u.speed(speed_model), color=_LINE_COLOURS[(len(lines) + i) % len(_LINE_COLOURS)],
                    ls="-.", lw=1.4, label=f"{name}: the free whirl ω mirrored to {m}x − ω/Ω")
        if lines or mirrored:
            # below the axes (and their order label), so the map stays unhidden
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16),
                      ncol=min(3, len(lines) + len(mirrored)),
                      title="expected order lines (solid: added, dashed: lookalike; dash-dot: a rotating "
                      "asymmetry turns the free whirl ω into 2Ω − ω, between 1x and 2x)", title_fontsize=7)
        ax.set_xlabel("rotation order (+ forward, - backward)")
        ax.set_ylabel(u.label("speed", u.speed_unit))
        ax.set_title(f"order map of the {which}-model residual")
        return fig

    #: effects whose moment mirrors a whirl ``z ~ e^{i w t}`` into ``e^{i (m Omega - w) t}``
    #: (``conj(z) e^{i m phi}``): a rotating asymmetry (m = 2); its residual sits there, not at
    #: its declared 1x/2x, when the record holds free whirl (the crack's opening excites it)
    MIRRORING: ClassVar[dict[str, int]] = {"asymmetry": 2, "breathing_crack": 2}

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
        fig, ax = self._ax(ax)
        comp = self.before if which == "before" else self.after
        r = first_rows(comp.residual, self.equation)
        ac = autocorrelation(r, max_lag)
        dt = self.data.meas.dt
        u = self.plot_units()
        lags = np.arange(len(ac)) * dt * u.time_factor
        ax.plot(lags, ac, lw=1)
        b = 1.96 / math.sqrt(len(r))
        ax.axhspan(-b, b, color="grey", alpha=0.3, label="95 % bounds (white noise)")
        ax.set_xlabel(u.label("lag", u.time_unit))
        ax.set_ylabel("autocorrelation (normalised)")
        ax.legend(fontsize=8)
        ax.set_title(f"residual autocorrelation ({which} model)")
        return fig

    def plot_candidates(self, ax=None):
        """The ranking: -log10 p of adding each candidate, with the Bonferroni line."""
        fig, ax = self._ax(ax)
        c = self.candidates
        names = [x.effect for x in c]
        vals = [max(-x.log10_p, 1e-3) for x in c]
        colors = ["C3" if x.effect in self.missing else "C7" for x in c]
        ax.barh(names, vals, color=colors)
        ax.set_xscale("log")
        ax.axvline(-math.log10(self.alpha / max(1, len(c))), color="k", ls="--", lw=1, label="alpha / n")
        ax.invert_yaxis()
        ax.set_xlabel(r"$-\log_{10} p$ of adding the effect")
        ax.legend(fontsize=8)
        ax.set_title("which effect is missing (red: added)")
        return fig

    def plot_before_after(self, ax=None, zoom: bool = True):
        """Equation-error RMS and free-run fit % along the forward selection; without
        ``ax`` (or with a pair of axes) also the residual of the starting and the final
        model over time, zoomed where the starting model failed most."""
        if ax is None:
            import matplotlib.pyplot as plt

            fig, axes = plt.subplots(2, 1, figsize=(8, 7.5), gridspec_kw={"height_ratios": [2, 3], "hspace": 0.35})
        else:
            axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
            fig = axes[0].figure
        ax = axes[0]
        steps = [self.before, *self.steps]
        labels = ["start"] + [f"+ {e}" for e in self.missing]
        x = np.arange(len(steps))
        ax.bar(x - 0.2, [s.fit_percent for s in steps], 0.4, color="C0", label="free-run fit %")
        ax.set_ylabel("free-run fit (%)")
        ax2 = ax.twinx()
        ax2.bar(x + 0.2, [s.rms for s in steps], 0.4, color="C3", label="equation RMS")
        ax2.set_ylabel("equation error RMS (dimensionless)")
        ax.set_xticks(x, labels, rotation=15, fontsize=8)
        ax.set_title("before and after adding the missing effects")
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax2.legend(h1 + h2, l1 + l2, fontsize=8, loc="lower right")  # on top of both bar sets
        if len(axes) > 1:
            self._residual_change(axes[1], zoom)
        return fig

    def _residual_change(self, ax, zoom: bool = True) -> None:
        """The starting and the final model's residual (first equation) over time, with the
        noise floor, and a zoom on the stretch where the starting model fails most."""
        u = self.plot_units()
        m = self.data.meas
        t = u.time(m.t)
        r0 = first_rows(self.before.residual, self.equation)
        r1 = first_rows(self.after.residual, self.equation)
        ax.plot(t, r0, lw=0.3, color="C3", label=f"starting model (RMS {self.before.rms:.3g})")
        ax.plot(t, r1, lw=0.3, color="C0", label=f"final model (RMS {self.after.rms:.3g})")
        ax.axhspan(-2 * self.noise_floor, 2 * self.noise_floor, color="0.5", alpha=0.25,
                   label=f"±2x the noise floor: the white-noise RMS of the residual, {self.noise_floor:.3g} "
                   "(dimensionless moment)")
        ax.set_xlabel(u.label("t", u.time_unit))
        ax.set_ylabel("equation residual (dimensionless)")
        ax.legend(fontsize=7, loc="upper left", markerscale=4)
        ax.set_title("residual before and after", fontsize=9)
        if zoom and len(t) > 50:
            # the stretch (a tenth of the record) with the largest starting-model misfit
            n = max(10, len(t) // 10)
            energy = np.convolve(r0 * r0, np.ones(n), mode="valid")
            k = int(np.argmax(energy))
            inset = ax.inset_axes([0.58, 0.55, 0.4, 0.42])
            inset.plot(t[k:k + n], r0[k:k + n], lw=0.4, color="C3")
            inset.plot(t[k:k + n], r1[k:k + n], lw=0.4, color="C0")
            inset.tick_params(labelsize=6)
            inset.set_title("zoom: where the starting model fails most", fontsize=7)
            ax.indicate_inset_zoom(inset, edgecolor="0.5")

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

    def _verdict_html(self) -> str:
        """The verdict section of the report: the word, its sentence, the residual over the
        noise floor, what is left (order lines, bands), the candidates turned down, the notes.

        Every string from data or user input (effect names, rules, notes) is escaped.
        """
        verdict = str(self.verdict)
        template = VERDICT_TEXT.get(verdict)
        sentence = template.format(ratio=self.rms_ratio_after, floor=self.noise_floor) if template else ""
        parts = [
            f"<section id='verdict' class='verdict verdict-{esc(verdict)}'>",
            "<h2>Verdict</h2>",
            f"<p class='verdict-word'>{esc(verdict)}</p>",
            f"<p class='verdict-text'>{esc(sentence)}</p>",
            f"<p class='verdict-ratio'>Final residual RMS: <b>{_num(self.rms_ratio_after, '.3g')}&times;</b> the "
            f"noise floor ({_num(self.noise_floor, '.3g')}); starting model: "
            f"{_num(self.rms_ratio_before, '.3g')}&times;.</p>",
        ]
        if math.isfinite(self.ip_estimate):
            se = (f" &plusmn; {_num(1.96 * self.ip_standard_error, '.2g')} (95 %)"
                  if math.isfinite(self.ip_standard_error) else "")
            parts.append(f"<p>Inertia ratio ip = {_num(self.ip, 'g')}; the gyroscopic moment in the data gives "
                         f"{_num(self.ip_estimate, '.4f')}{se}.</p>")
        left = self.unexplained or {}
        if verdict in ("partly_explained", "unexplained") or left:
            orders = left.get("orders") or []
            parts.append("<h3>What is left, by rotation order</h3>")
            if orders:
                rows = "".join(
                    f"<tr><td>{esc(_order(o.get('order')))}</td><td>{esc(o.get('direction', ''))}</td>"
                    f"<td>{_num(100 * o.get('share', math.nan), '.0f')} %</td></tr>"
                    for o in orders
                )
                parts.append("<table class='orders'><tr><th>order</th><th>whirl</th>"
                             f"<th>share of the energy above the noise</th></tr>{rows}</table>")
            else:
                parts.append("<p>No single rotation-order line stands out.</p>")
            bands = left.get("bands") or []
            parts.append("<h3>Where the residual stands out</h3>")
            if bands:
                rows = "".join(
                    f"<tr><td>{_num(w.get('t_start'), '.0f')}&ndash;{_num(w.get('t_end'), '.0f')}</td>"
                    f"<td>{_num(w.get('speed_min'), '.3g')}&ndash;{_num(w.get('speed_max'), '.3g')}</td>"
                    f"<td>{_num(w.get('peak_rms_over_floor'), '.1f')}&times;</td></tr>"
                    for w in bands
                )
                parts.append("<table class='bands'><tr><th>t</th><th>speed</th><th>peak RMS / floor</th></tr>"
                             f"{rows}</table>")
            else:
                parts.append("<p>No band of time stands above the floor.</p>")
        rows = "".join(
            f"<tr><td>{esc(r.get('effect', ''))}</td><td>{esc(r.get('rule', ''))}</td>"
            + (f"<td>{esc(r['round'])}</td>" if r.get("round") else "") + "</tr>"
            for r in self.rejected
        ) or "<tr><td colspan=3>none</td></tr>"
        parts.append("<h3>Candidates turned down</h3>"
                     "<table class='rejected'><tr><th>effect</th><th>rule that rejected it</th>"
                     f"<th>round (the last that tried it)</th></tr>{rows}</table>")
        if self.notes:
            items = "".join(f"<li>{esc(n)}</li>" for n in self.notes)
            parts.append(f"<h3>Notes</h3><ul class='notes'>{items}</ul>")
        parts.append("</section>")
        return "\n".join(parts)

    def _lookalikes_html(self) -> str:
        """The section "Told apart from its lookalikes": for every added effect that has
        lookalikes, its declared orders, the residual's order lines before it was added,
        its main order's amplitude by speed band and each lookalike's status.  Empty where
        no added effect has a lookalike.  Every string is escaped."""
        evidence = [ev for ev in (getattr(self, "lookalikes", None) or []) if ev.get("lookalikes")]
        if not evidence:
            return ""
        parts = ["<section id='lookalikes' class='lookalikes'>", "<h2>Told apart from its lookalikes</h2>"]
        for ev in evidence:
            name = ev.get("effect", "")
            declared = ev.get("declared_orders") or []
            parts.append(f"<div class='lookalike-evidence' data-effect='{esc(name)}'>")
            parts.append(f"<h3>{esc(name)}</h3>")
            parts.append(
                f"<p class='declared'>Added: <b>{esc(name)}</b>; it declares the order lines "
                f"{esc(_signed_orders(declared))} (log10 p {_num(ev.get('log10_p'), '.4g')}, removes "
                f"{_pct(ev.get('energy_drop'), '.1f')} of the equation error, free-run fit "
                f"{_num(ev.get('fit_gain'), '+.1f')} points).</p>")
            orders = ev.get("residual_orders") or []
            if orders:
                rows = "".join(
                    f"<tr><td>{esc(_order(o.get('order')))}</td><td>{esc(o.get('direction', ''))}</td>"
                    f"<td>{_pct(o.get('share'), '.0f')}</td></tr>"
                    for o in orders
                )
                parts.append("<p>The residual before adding it, by rotation order:</p>"
                             "<table class='lookalike-orders'><tr><th>order</th><th>whirl</th>"
                             f"<th>share of the energy above the noise</th></tr>{rows}</table>")
            else:
                parts.append("<p>No single rotation-order line stood out in the residual before adding it.</p>")
            by_speed = ev.get("residual_by_speed") or []
            if by_speed:
                main = by_speed[0].get("order")
                rows = "".join(
                    f"<tr><td>{_num(b.get('speed_min'), '.3g')}&ndash;{_num(b.get('speed_max'), '.3g')}</td>"
                    f"<td>{_num(b.get('amplitude'), '.3g')}</td></tr>"
                    for b in by_speed
                )
                parts.append(f"<p>Amplitude of its main line ({esc(_signed_orders([main]))}) in the residual, "
                             "by speed band:</p>"
                             "<table class='lookalike-speed'><tr><th>speed band</th><th>amplitude</th></tr>"
                             f"{rows}</table>")
            where = ev.get("acts_where") or {}
            if where.get("reading"):
                scanned = ", ".join(f"{k} = {_num(v, '.4g')}" for k, v in (where.get("scanned") or {}).items())
                first, last = where.get("first_contact") or {}, where.get("last_contact") or {}
                parts.append(
                    f"<p class='acts-where'>Scanned: {esc(scanned)}. {esc(where['reading'])}. Where it acts the "
                    f"residual held {_pct(where.get('backward_1x_share'), '.0f')} backward 1x and "
                    f"{_pct(where.get('half_order_share'), '.0f')} at 1/2x; contact from speed "
                    f"{_num(first.get('speed'), '.3g')} to {_num(last.get('speed'), '.3g')} in this "
                    f"{esc(where.get('sweep', ''))}.</p>")
            rows = "".join(
                f"<tr><td>{esc(lk.get('effect', ''))}</td><td>{esc(lk.get('status', ''))}</td>"
                f"<td>{_num(lk.get('log10_p'), '.4g')}</td>"
                f"<td>{_pct(lk.get('energy_drop'), '.2g')}</td>"
                f"<td>{esc(_signed_orders(lk['declared_orders'])) if lk.get('declared_orders') is not None else '-'}"
                "</td></tr>"
                for lk in ev.get("lookalikes") or []
            )
            parts.append("<table class='lookalike-status'><tr><th>lookalike</th><th>status</th><th>log10 p</th>"
                         f"<th>energy drop</th><th>declared orders</th></tr>{rows}</table>")
            parts.append("</div>")
        parts.append("</section>")
        return "\n".join(parts)

    def report(self, path: str | Path, *, overwrite: bool = False, preamble: str = "") -> Path:
        """A self-contained HTML report (figures embedded as PNG).

        ``preamble``: HTML put after the title (a rig diagnosis puts its 1X-vector section
        there: criticals, Bode and polar plots in the rig's units).
        """
        path = check_writable(path, overwrite=overwrite)  # before the figures are drawn
        imgs = {name: figure_tag(fig, name) for name, fig in self.figures().items()}

        decided = self.decisions()
        cand_rows = "".join(
            f"<tr class='{'missing' if c.effect in self.missing else ''}'><td>{esc(c.effect)}</td><td>{c.F:.4g}</td>"
            f"<td>{c.log10_p:.4g}</td><td>{c.rms_after:.4g}</td><td>{fit_cell(c)}</td>"
            f"<td>{c.correlation:.2f}</td><td>{c.order_overlap:.2f}</td><td>{esc(decided.get(c.effect, 'not decided'))}</td>"
            f"<td>{esc(c.story)}</td></tr>"
            for c in self.candidates
        )
        win_rows = "".join(
            f"<tr><td>{w['t_start']:.1f}</td><td>{w['t_end']:.1f}</td><td>{w['peak_rms_over_floor']:.1f}</td></tr>"
            for w in self.windows
        ) or "<tr><td colspan=3>none</td></tr>"
        bias = self.after.eiv_bias
        coef_rows = "".join(
            f"<tr><td>{esc(c)}</td><td>{v:.5g}</td><td>{s:.2g}</td>"
            + (f"<td>{bias[j]:+.2g}</td>" if bias is not None else "") + "</tr>"
            for j, (c, v, s) in enumerate(
                zip(self.after.columns, self.after.coefficients, self.after.standard_errors, strict=True))
        )
        coef_head = ("<tr><th>coefficient</th><th>estimate</th><th>std. error</th>"
                     + ("<th>noise (errors-in-variables) bias removed</th>" if bias is not None else "") + "</tr>")
        u = self.plot_units()
        units_note = (f"Time in s and speed in rpm (time scale {self.time_scale:.6g} from the identified "
                      "natural frequency)." if u.time_unit == "s" else
                      "Dimensionless units: time in 1/natural frequency, speed in rad per time unit, angles in rad.")
        missing = ", ".join(
            f"<b>{esc(e)}</b>" + (f" (from t ≈ {self.onset[e]:.0f})" if self.onset.get(e) is not None else "")
            for e in self.missing
        ) or "none"
        body = f"""<h1>rotor-id diagnosis</h1>
{preamble}
{self._verdict_html()}
{self._lookalikes_html()}
<h2>Summary</h2>
<p>Data: {esc(str(self.source))}; ip = {self.ip:g}; alpha = {self.alpha:g}; informative window t &ge; {self.t_start:g}.</p>
<p>Starting model: {esc(', '.join(self.start_model))}. Missing: {missing}. Final model: {esc(', '.join(self.model))}.</p>
<table><tr><th></th><th>equation RMS</th><th>R²</th><th>free-run fit %</th></tr>
<tr><td>before</td><td>{self.before.rms:.4g}</td><td>{self.before.r2:.4f}</td><td>{self.before.fit_percent:.1f}</td></tr>
<tr><td>after</td><td>{self.after.rms:.4g}</td><td>{self.after.r2:.4f}</td><td>{self.after.fit_percent:.1f}</td></tr></table>
<h2>Compare</h2>{imgs['compare']}
<h2>Where it fails</h2>{imgs['residual']}{imgs['order_map']}{imgs['autocorrelation']}
<p>Windows where the residual stands above the noise floor ({self.noise_floor:.3g}):</p>
<table><tr><th>t start</th><th>t end</th><th>peak RMS / floor</th></tr>{win_rows}</table>
<h2>Which effect is missing</h2>{imgs['candidates']}
<table><tr><th>effect</th><th>F</th><th>log10 p</th><th>RMS after</th><th>fit % after</th><th>corr.</th><th>order overlap</th><th>decision (round)</th><th>physical story</th></tr>{cand_rows}</table>
<h2>Before and after</h2>{imgs['before_after']}
<p>The final model's residual (shaded where it still stands above 2&times; the noise floor):</p>
{imgs['residual_after']}
<table class='coefficients'>{coef_head}{coef_rows}</table>
<h2>Bode and polar plots</h2>
<p>1X vectors per revolution (least squares against the spin angle between keyphasor marks) of the
measured angles and of the starting and final models' free runs; phase lag as instruments show it
(x = A cos(&phi; &minus; lag)). {esc(units_note)}</p>
{imgs['bode']}{imgs['polar']}
<h2>Orbits</h2>
<p>&theta;x (vertical) against &theta;y (horizontal) over one revolution below, at and above the critical:
unfiltered (mean removed) and 1X-filtered; the dot is the keyphasor (&phi; a multiple of 2&pi;), the arrow
the direction of the whirl.</p>
{imgs['orbit']}
<h2>Waterfall</h2>
<p>Spectra of the measured z = &theta;y + i &theta;x over 8-revolution blocks against speed: positive
frequencies whirl forward, negative backward; dotted: the 1x and 2x lines.</p>
{imgs['waterfall']}
<h2>Campbell diagram</h2>
<p>Whirl frequencies of the final model's linear fixed-frame part against speed, the 1x and 2x lines and
the criticals where 1x crosses a branch; dots: free-whirl peaks found in the measured waterfall.
A rotating-frame asymmetry (crack) would need a Floquet analysis and is not in these branches.</p>
{imgs['campbell']}
<h2>Parameter tracks</h2>
<p>The recursive QR identifier run over the data with the final model's effects: every coefficient
after every sample, bold where its effect's F test is significant (white-residual test: optimistic on
coloured residuals; the verdict uses HAC tests), and the batch estimate &plusmn; 95 % at the end.</p>
{imgs['parameter_tracks']}
<pre>{esc(self.summary())}</pre>"""
        return write_page(path, "rotor-id diagnosis", body, extra_style=_STYLE, overwrite=overwrite)


def _first_axes(fig, ax):
    """The axes a plot drew first on: the caller's (one, or the first of several) or the
    new figure's first."""
    if ax is None:
        return fig.axes[0]
    return ax[0] if isinstance(ax, (list, tuple, np.ndarray)) else ax


#: colours of the expected order lines on the order map (visible on viridis)
_LINE_COLOURS = ("#e41a1c", "#ff7f00", "#f781bf", "#000000", "#00e5ff", "#a65628")


def _declared_orders(name) -> tuple:
    """The signed rotation orders the library declares for effect ``name`` (``()`` if unknown)."""
    from ..effects import EFFECTS

    eff = EFFECTS.get(name)
    return tuple(getattr(eff, "orders", ()) or ()) if eff is not None else ()


def _signed_orders(orders) -> str:
    """Signed rotation orders in words: ``+2x forward, -2x backward``; ``none`` for none."""
    words = []
    for o in orders or []:
        try:
            v = float(o)
        except (TypeError, ValueError):
            words.append(str(o))
            continue
        words.append("0x static" if v == 0 else f"{v:+g}x {'forward' if v > 0 else 'backward'}")
    return ", ".join(words) or "none"


def _pct(x, fmt: str) -> str:
    """A fraction as a percentage (``12.5 %``); ``-`` where there is none (None, NaN)."""
    try:
        v = 100 * float(x)
    except (TypeError, ValueError):
        return "-"
    return f"{format(v, fmt)} %" if math.isfinite(v) else "-"


def _num(x, fmt: str) -> str:
    """A number formatted with ``fmt``; ``-`` where there is none (None, not a number)."""
    try:
        return format(float(x), fmt)
    except (TypeError, ValueError):
        return "-"


def _order(o) -> str:
    """A rotation order as the report writes it: ``1x``, ``1.5x``."""
    try:
        return f"{float(o):g}x"
    except (TypeError, ValueError):
        return f"{o}x"


def fit_cell(c) -> str:
    """A candidate's free-run fit %; a free run that diverged has none (not "-100.0")."""
    comp = getattr(c, "comparison", None)
    if getattr(comp, "diverged", False) or not math.isfinite(c.fit_percent_after) or c.fit_percent_after <= -100.0:
        return "diverged"
    return f"{c.fit_percent_after:.1f}"
