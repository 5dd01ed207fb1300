"""Figures and the self-contained HTML report of a diagnosis."""

from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path

import numpy as np

from ..outputs import atomic_write, atomic_write_text, check_writable
from .orders import _first_rows, autocorrelation, complex_rows, order_map


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

    def plot_compare(self, ax=None, which: str = "after"):
        """Measured vs model amplitude |theta| against speed (free-run simulation)."""
        fig, ax = self._ax(ax)
        m = self.data.meas
        ax.plot(m.phi_dot, np.hypot(m.theta_x, m.theta_y), "k", lw=1.2, label="measured")
        for comp, style, label in ((self.before, "C3--", "starting model"), (self.after, "C0", "final model")):
            if which in ("after", "both") or comp is self.before:
                if comp.simulated is not None:
                    s = comp.simulated
                    ax.plot(s.phi_dot, np.hypot(s.theta_x, s.theta_y), style, lw=1,
                            label=f"{label}: {', '.join(comp.model)} (fit {comp.fit_percent:.0f} %)")
        ax.set_xlabel("spin speed (dimensionless)")
        ax.set_ylabel(r"amplitude $|\theta|$")
        ax.legend(fontsize=7)
        ax.set_title("measured vs model response (free run)")
        return fig

    def plot_residual(self, ax=None, which: str = "before"):
        """Equation-error residual against time (and speed on a top axis)."""
        fig, ax = self._ax(ax)
        comp = self.before if which == "before" else self.after
        t = np.repeat(self.data.meas.t, 2 if self.equation == "both" else 1)
        ax.plot(t, comp.residual, lw=0.3, color="C3" if which == "before" else "C0")
        for w in self.windows if which == "before" else []:
            ax.axvspan(w["t_start"], w["t_end"], color="orange", alpha=0.2)
        ax.set_xlabel("t")
        ax.set_ylabel("equation residual")
        ax.set_title(f"residual of the {which} model ({', '.join(comp.model)}); shaded: above noise floor")
        t_m, w_m = self.data.meas.t, self.data.meas.phi_dot
        if np.all(np.diff(w_m) > 0):  # a speed axis only where speed maps one-to-one onto time
            top = ax.secondary_xaxis(
                "top", functions=(lambda x: np.interp(x, t_m, w_m), lambda s: np.interp(s, w_m, t_m)))
            top.set_xlabel("speed")
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
        speeds, orders, amp = order_map(m.t, m.phi, m.phi_dot, complex_rows(comp.residual, self.equation))
        if amp.size:
            mesh = ax.pcolormesh(orders, speeds, np.log10(amp + 1e-12), shading="nearest", cmap="viridis")
            fig.colorbar(mesh, ax=ax, label="log10 amplitude")
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
        if lines:
            # below the axes (and their order label), so the map stays unhidden
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=min(3, len(lines)),
                      title="expected order lines (solid: added, dashed: lookalike)", title_fontsize=7)
        ax.set_xlabel("rotation order (+ forward, - backward)")
        ax.set_ylabel("speed")
        ax.set_title(f"order map of the {which}-model residual")
        return fig

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
        r = _first_rows(comp.residual, self.equation)
        ac = autocorrelation(r, max_lag)
        dt = self.data.meas.dt
        lags = np.arange(len(ac)) * dt
        ax.plot(lags, ac, lw=1)
        b = 1.96 / math.sqrt(len(r))
        ax.axhspan(-b, b, color="grey", alpha=0.3, label="95 % bounds (white noise)")
        ax.set_xlabel("lag (time)")
        ax.set_ylabel("autocorrelation")
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

    def plot_before_after(self, ax=None):
        """Equation-error RMS and free-run fit % along the forward selection."""
        fig, ax = self._ax(ax)
        steps = [self.before, *self.steps]
        labels = ["start"] + [f"+ {e}" for e in self.missing]
        x = np.arange(len(steps))
        ax.bar(x - 0.2, [s.fit_percent for s in steps], 0.4, color="C0", label="free-run fit %")
        ax.set_ylabel("fit %")
        ax2 = ax.twinx()
        ax2.bar(x + 0.2, [s.rms for s in steps], 0.4, color="C3", label="equation RMS")
        ax2.set_ylabel("equation error RMS")
        ax.set_xticks(x, labels, rotation=15, fontsize=8)
        ax.set_title("before and after adding the missing effects")
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax2.legend(h1 + h2, l1 + l2, fontsize=8, loc="lower right")  # on top of both bar sets
        return fig

    #: the figures :meth:`figures` draws, by file name
    FIGURES = ("compare", "residual", "order_map", "autocorrelation", "candidates", "before_after")

    def figures(self) -> dict[str, object]:
        return {
            "compare": self.plot_compare(which="both"),
            "residual": self.plot_residual(),
            "order_map": self.plot_order_map(),
            "autocorrelation": self.plot_autocorrelation(),
            "candidates": self.plot_candidates(),
            "before_after": self.plot_before_after(),
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
        from .result import VERDICT_TEXT  # result imports this module

        verdict = str(self.verdict)
        template = VERDICT_TEXT.get(verdict)
        sentence = template.format(ratio=self.rms_ratio_after, floor=self.noise_floor) if template else ""
        parts = [
            f"<section id='verdict' class='verdict verdict-{_e(verdict)}'>",
            "<h2>Verdict</h2>",
            f"<p class='verdict-word'>{_e(verdict)}</p>",
            f"<p class='verdict-text'>{_e(sentence)}</p>",
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
                    f"<tr><td>{_e(_order(o.get('order')))}</td><td>{_e(o.get('direction', ''))}</td>"
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
            f"<tr><td>{_e(r.get('effect', ''))}</td><td>{_e(r.get('rule', ''))}</td></tr>" for r in self.rejected
        ) or "<tr><td colspan=2>none</td></tr>"
        parts.append("<h3>Candidates turned down</h3>"
                     f"<table class='rejected'><tr><th>effect</th><th>rule that rejected it</th></tr>{rows}</table>")
        if self.notes:
            items = "".join(f"<li>{_e(n)}</li>" for n in self.notes)
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
            parts.append(f"<div class='lookalike-evidence' data-effect='{_e(name)}'>")
            parts.append(f"<h3>{_e(name)}</h3>")
            parts.append(
                f"<p class='declared'>Added: <b>{_e(name)}</b>; it declares the order lines "
                f"{_e(_signed_orders(declared))} (log10 p {_num(ev.get('log10_p'), '.4g')}, removes "
                f"{_pct(ev.get('energy_drop'), '.1f')} of the equation error, free-run fit "
                f"{_num(ev.get('fit_gain'), '+.1f')} points).</p>")
            orders = ev.get("residual_orders") or []
            if orders:
                rows = "".join(
                    f"<tr><td>{_e(_order(o.get('order')))}</td><td>{_e(o.get('direction', ''))}</td>"
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
                parts.append(f"<p>Amplitude of its main line ({_e(_signed_orders([main]))}) in the residual, "
                             "by speed band:</p>"
                             "<table class='lookalike-speed'><tr><th>speed band</th><th>amplitude</th></tr>"
                             f"{rows}</table>")
            rows = "".join(
                f"<tr><td>{_e(lk.get('effect', ''))}</td><td>{_e(lk.get('status', ''))}</td>"
                f"<td>{_num(lk.get('log10_p'), '.4g')}</td>"
                f"<td>{_pct(lk.get('energy_drop'), '.2g')}</td>"
                f"<td>{_e(_signed_orders(lk['declared_orders'])) if lk.get('declared_orders') is not None else '-'}"
                "</td></tr>"
                for lk in ev.get("lookalikes") or []
            )
            parts.append("<table class='lookalike-status'><tr><th>lookalike</th><th>status</th><th>log10 p</th>"
                         f"<th>energy drop</th><th>declared orders</th></tr>{rows}</table>")
            parts.append("</div>")
        parts.append("</section>")
        return "\n".join(parts)

    def report(self, path: str | Path, *, overwrite: bool = False) -> Path:
        """A self-contained HTML report (figures embedded as PNG)."""
        import matplotlib.pyplot as plt

        path = check_writable(path, overwrite=overwrite)  # before the figures are drawn
        imgs = {}
        for name, fig in self.figures().items():
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
            plt.close(fig)
            imgs[name] = base64.b64encode(buf.getvalue()).decode()

        def img(name):
            return f'<img alt="{name}" src="data:image/png;base64,{imgs[name]}">'

        cand_rows = "".join(
            f"<tr class='{'missing' if c.effect in self.missing else ''}'><td>{_e(c.effect)}</td><td>{c.F:.4g}</td>"
            f"<td>{c.log10_p:.4g}</td><td>{c.rms_after:.4g}</td><td>{c.fit_percent_after:.1f}</td>"
            f"<td>{c.correlation:.2f}</td><td>{c.order_overlap:.2f}</td><td>{html.escape(c.story)}</td></tr>"
            for c in self.candidates
        )
        win_rows = "".join(
            f"<tr><td>{w['t_start']:.1f}</td><td>{w['t_end']:.1f}</td><td>{w['peak_rms_over_floor']:.1f}</td></tr>"
            for w in self.windows
        ) or "<tr><td colspan=3>none</td></tr>"
        bias = self.after.eiv_bias
        coef_rows = "".join(
            f"<tr><td>{_e(c)}</td><td>{v:.5g}</td><td>{s:.2g}</td>"
            + (f"<td>{bias[j]:+.2g}</td>" if bias is not None else "") + "</tr>"
            for j, (c, v, s) in enumerate(
                zip(self.after.columns, self.after.coefficients, self.after.standard_errors, strict=True))
        )
        coef_head = ("<tr><th>coefficient</th><th>estimate</th><th>std. error</th>"
                     + ("<th>noise (errors-in-variables) bias removed</th>" if bias is not None else "") + "</tr>")
        missing = ", ".join(
            f"<b>{_e(e)}</b>" + (f" (from t ≈ {self.onset[e]:.0f})" if self.onset.get(e) is not None else "")
            for e in self.missing
        ) or "none"
        doc = f"""<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">
<title>rotor-id diagnosis</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:auto;padding:1em;color:#222}}
table{{border-collapse:collapse;margin:.5em 0}}td,th{{border:1px solid #bbb;padding:3px 8px;font-size:13px}}
tr.missing{{background:#fde0dc}}
section.verdict{{border:2px solid #888;border-radius:6px;padding:.3em 1em;margin:1em 0}}
p.verdict-word{{font-size:2em;font-weight:bold;margin:.2em 0}}
.verdict-explained,.verdict-explained_after_adding{{border-color:#2a8a3a!important}}
.verdict-partly_explained{{border-color:#d98a00!important}}.verdict-unexplained{{border-color:#c0392b!important}}
.verdict-explained p.verdict-word,.verdict-explained_after_adding p.verdict-word{{color:#2a8a3a}}
.verdict-partly_explained p.verdict-word{{color:#d98a00}}.verdict-unexplained p.verdict-word{{color:#c0392b}}img{{max-width:100%}}pre{{background:#f4f4f4;padding:.5em}}</style></head><body>
<h1>rotor-id diagnosis</h1>
{self._verdict_html()}
{self._lookalikes_html()}
<h2>Summary</h2>
<p>Data: {html.escape(str(self.source))}; ip = {self.ip:g}; alpha = {self.alpha:g}; informative window t &ge; {self.t_start:g}.</p>
<p>Starting model: {_e(', '.join(self.start_model))}. Missing: {missing}. Final model: {_e(', '.join(self.model))}.</p>
<table><tr><th></th><th>equation RMS</th><th>R²</th><th>free-run fit %</th></tr>
<tr><td>before</td><td>{self.before.rms:.4g}</td><td>{self.before.r2:.4f}</td><td>{self.before.fit_percent:.1f}</td></tr>
<tr><td>after</td><td>{self.after.rms:.4g}</td><td>{self.after.r2:.4f}</td><td>{self.after.fit_percent:.1f}</td></tr></table>
<h2>Compare</h2>{img('compare')}
<h2>Where it fails</h2>{img('residual')}{img('order_map')}{img('autocorrelation')}
<p>Windows where the residual stands above the noise floor ({self.noise_floor:.3g}):</p>
<table><tr><th>t start</th><th>t end</th><th>peak RMS / floor</th></tr>{win_rows}</table>
<h2>Which effect is missing</h2>{img('candidates')}
<table><tr><th>effect</th><th>F</th><th>log10 p</th><th>RMS after</th><th>fit % after</th><th>corr.</th><th>order overlap</th><th>physical story</th></tr>{cand_rows}</table>
<h2>Before and after</h2>{img('before_after')}
<table class='coefficients'>{coef_head}{coef_rows}</table>
<pre>{html.escape(self.summary())}</pre>
</body></html>"""
        return atomic_write_text(path, doc, overwrite=overwrite)


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


def _e(x) -> str:
    """``x`` as text, HTML-escaped (quotes too): for every string from data or user input."""
    return html.escape(str(x))


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
