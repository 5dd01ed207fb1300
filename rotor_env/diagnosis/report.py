"""The self-contained HTML report of a diagnosis: the verdict, the lookalikes, the page.

:class:`DiagnosisReport` is a mixin of :class:`~rotor_env.diagnosis.result.Diagnosis`
(next to :class:`~rotor_env.diagnosis.figures.DiagnosisFigures`, whose figures the page
embeds): it writes the page's sections from the diagnosis's fields, every string from
data escaped, and the page through :mod:`rotor_env.pages` (one shell, one figure embedder).
"""

from __future__ import annotations

import math
from pathlib import Path

from ..outputs import check_writable
from ..pages import esc, figure_tag, write_page
from ..plots.diagnosis import speed_axis_functions  # noqa: F401  (its old place: still importable here)
from .verdict import VERDICT_TEXT

__all__ = ["DiagnosisReport", "fit_cell"]

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


class DiagnosisReport:
    """The HTML page of :class:`~rotor_env.diagnosis.Diagnosis` (a mixin: reads its fields
    and draws its figures with :meth:`~rotor_env.diagnosis.figures.DiagnosisFigures.figures`)."""

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
