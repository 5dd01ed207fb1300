"""The live view of ``rotor-id monitor`` in a terminal (rich): flags, coefficients, CUSUMs, alarms.

With a rig stream (``--rig``) times are shown in s and speeds in rpm (the events'
``t_s``, ``rpm``, ``t_alarm_s``, ``t_onset_s`` fields).
"""

from __future__ import annotations

from typing import Any

from .core import ALARM_EVENTS, alarm_words


class LiveView:
    """A rich ``Live`` table refreshed at every status line; alarms are kept below it.

    Piped (standard output not a terminal) there is nothing to refresh: each alarm is
    printed as a line when it comes and the table once at the end, each on its own line.
    """

    def __init__(self, source: str) -> None:
        from rich.console import Console

        self.source = source
        self.console = Console(stderr=False)
        self.live = None
        self.monitor = None
        self.alarms: list[dict] = []
        self.last_status: dict | None = None
        self.clock = None

    def start(self, monitor, clock=None) -> None:
        """Show ``monitor``; ``clock`` (a :class:`~rotor_env.measurements.rig_stream.RigClock`): in s and rpm."""
        from rich.live import Live

        self.monitor = monitor
        self.clock = clock
        if not self.console.is_terminal:
            return  # piped: lines, no live refresh (show / stop print them)
        self.live = Live(self._render(), console=self.console, refresh_per_second=4, transient=False)
        self.live.start()

    def show(self, event: dict) -> None:
        if event["event"] in ALARM_EVENTS:
            self.alarms.append(event)
            if self.live is None and self.monitor is not None:  # piped: the alarm as a line now
                self.console.print(_alarm_line(event))
        elif event["event"] == "status":
            self.last_status = event
        elif event["event"] == "error":
            self.console.print(f"[red]error:[/red] {event['message']}")
        if self.live is not None:
            self.live.update(self._render())

    def _render(self) -> Any:
        from rich.console import Group
        from rich.table import Table

        st = self.last_status
        title = f"rotor-id monitor — {self.source}"
        if st is not None and "t_s" in st:
            title += f"   t = {st['t_s']:.3f} s, {st['rpm']:.0f} rpm, noise floor {st['noise_floor']:.3g}"
        elif st is not None:
            title += f"   t = {st['t']:.2f}, speed {st['speed']:.3f}, noise floor {st['noise_floor']:.3g}"
        table = Table(title=title)
        for col in ("effect", "coefficients", "significant", "CUSUM"):
            table.add_column(col)
        mon = self.monitor
        if st is not None and mon is not None:
            for name in mon.effects:
                coef = ", ".join(f"{k} = {v:.4g}" for k, v in st["coefficients"][name].items())
                flag = "[green]yes[/green]" if st["significant"][name] else "no"
                table.add_row(name, coef, flag, f"{st['cusum'][name]:.2f} / {mon.threshold:.2f}")
        parts: list[Any] = [table]
        if st is not None and st.get("blind"):
            parts.append(f"[bold yellow]{st['blind']}[/bold yellow]")
        if self.alarms:
            a = self.alarms[-1]
            parts.append(f"[bold red]latest alarm[/bold red]: {_alarm_line(a)}; {len(self.alarms)} alarm(s) so far")
        else:
            parts.append("no alarm")
        return Group(*parts)

    def stop(self) -> None:
        if self.live is not None:
            self.live.stop()
            self.live = None
        elif self.monitor is not None:  # piped: the final table once
            self.console.print(self._render())

    def print_summary(self, summary: dict) -> None:
        end = f"t = {summary['t_s']:.3f} s ({summary['rpm']:.0f} rpm)" if "t_s" in summary else f"t = {summary['t']:.2f}"
        self.console.print(f"{summary['samples']} samples to {end}: {summary['alarms']} alarm(s)")
        if summary.get("unprocessed_samples"):
            self.console.print(f"  {summary['unprocessed_samples']} samples received after it not processed (the last "
                               "incomplete block, or stopped by Ctrl-C): a saved state keeps them")
        for e in summary["events"]:
            self.console.print(f"  {alarm_words(e)} {e['event']} at {_when(e)}")
        if summary.get("blind"):
            self.console.print(f"[bold yellow]{summary['blind']}[/bold yellow]")


def _values(values: dict) -> str:
    """``{"D": 0.03, "k": 1.0}`` -> ``"D = 0.03, k = 1"`` (not a Python dict repr)."""
    return ", ".join(f"{k} = {v:.4g}" if isinstance(v, (int, float)) else f"{k} = {v}" for k, v in values.items())


def _alarm_line(a: dict) -> str:
    """One alarm in words: effect, event, when, the value before and after."""
    if a["event"] == "unattributed":  # each candidate's values, as if it alone had changed
        each = "; ".join(f"{e}: {_values(a['value_before'][e])} -> {_values(a['value_after'][e])}"
                         for e in a["candidates"])
        return f"a change at {_when(a)}: {alarm_words(a)}; {each}"
    return f"{a['effect']} {a['event']} at {_when(a)}: {_values(a['value_before'])} -> {_values(a['value_after'])}"


def _when(e: dict) -> str:
    """An alarm's time (and onset): in s and rpm for a rig stream, else in time units."""
    if "t_alarm_s" in e:
        rpm = f", {e['rpm_alarm']:.0f} rpm" if "rpm_alarm" in e else ""
        return f"t = {e['t_alarm_s']:.3f} s{rpm} (onset {e['t_onset_s']:.3f} s)"
    return f"t = {e['t_alarm']:.2f} (onset {e['t_onset']:.2f})"
