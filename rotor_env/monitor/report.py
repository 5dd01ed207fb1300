"""A self-contained HTML page of a monitoring run: the alarms, the final model, the design."""

from __future__ import annotations

import json

from ..pages import esc, write_page
from .core import alarm_words


def write_report(monitor, path, *, source: str, overwrite: bool = False, clock=None) -> None:
    """Write the run's events and final state to ``path`` (every value escaped); ``clock``
    (a rig stream's :class:`~rotor_env.measurements.rig_stream.RigClock`): times in s and speeds in rpm."""
    s = monitor.summary()

    def when(t: float, speed: float | None = None) -> str:
        if clock is None:
            return f"{t:.2f}"
        rpm = f" ({clock.rpm(speed):.0f} rpm)" if speed is not None else ""
        return f"{clock.seconds(t):.3f} s{rpm}"

    rows = "".join(
        f"<tr><td>{esc(e['event'])}</td><td>{esc(alarm_words(e))}</td>"
        f"<td>{when(e['t_onset'], e['evidence'].get('speed_onset'))}</td>"
        f"<td>{when(e['t_alarm'], e['evidence'].get('speed_alarm'))}</td><td>{esc(json.dumps(e['value_before']))}</td>"
        f"<td>{esc(json.dumps(e['value_after']))}</td><td>{e['evidence']['log10_p']:.1f}</td></tr>"
        for e in monitor.events)
    end = (f"t = {s['t']:.2f} (speed {s['speed']:.3f})" if clock is None else
           f"t = {clock.seconds(s['t']):.3f} s ({clock.rpm(s['speed']):.0f} rpm; natural frequency "
           f"{clock.natural_rpm:g} rpm, the model's time unit 1/{clock.w_ref:.6g} s)")
    model = "".join(
        f"<tr><td>{esc(name)}</td><td>{esc(json.dumps(coef))}</td><td>{'yes' if s['significant'][name] else 'no'}"
        f"</td><td>{s['counted_blocks'][name]}</td></tr>" for name, coef in s["coefficients"].items())
    cfg = monitor.config
    blind = f"<p><b>{esc(s['blind'])}</b></p>" if s.get("blind") else ""
    body = f"""<h1>On-line monitoring of {esc(source)}</h1>
<p>{s['samples']} samples to {esc(end)}; equation-error noise floor
{s['noise_floor']:.3g}. CUSUM per effect, threshold {s['threshold']:.3f} for a target in-control ARL of
{cfg.arl0:g} samples (blocks of {cfg.block}); {s['alarms']} alarm(s).</p>{blind}
<h2>Alarms</h2><table><tr><th>event</th><th>effect</th><th>onset</th><th>alarm</th><th>before</th>
<th>after</th><th>log10 p</th></tr>{rows}</table>
<h2>Model at the end</h2><table><tr><th>effect</th><th>parameters</th><th>significant</th>
<th>blocks counted</th></tr>{model}</table>"""
    write_page(path, "rotor-id monitor", body, overwrite=overwrite)
