"""Progress of the long commands: one helper for all of them.

In a terminal a bar (tqdm, on stderr) per step of the work; otherwise (a pipe, a log file,
CI) a line on stderr every ``ROTOR_ID_PROGRESS_EVERY`` seconds (default 10; the first after
half of that), from a background thread, so that a step that reports nothing for a minute
is not a minute of silence.  Each line says what runs, how far it is (when the step knows
its total), the time so far and the time left *in that step*, estimated from the step's
own rate — or "time left not known" where the step has no total (never a guess).

The command line opens one :class:`Progress` per command (:func:`rotor_env.cli.main`); the
library reports its steps through the module functions :func:`step` and :func:`advance`,
which do nothing when no command is watching (a Python user's call stays silent).

    with Progress("rotor-id diagnose"):
        step("ranking candidates, round 1", total=11, unit="candidates")
        for c in candidates:
            ...
            advance()
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable
from typing import TextIO

__all__ = ["EVERY_ENV", "Progress", "active", "advance", "step"]

#: environment variable: seconds between two lines when not in a terminal (default 10)
EVERY_ENV = "ROTOR_ID_PROGRESS_EVERY"

_active: Progress | None = None


def active() -> Progress | None:
    """The :class:`Progress` of the running command, if any."""
    return _active


def step(what: str, total: float | None = None, unit: str = "") -> None:
    """A new step of the running command's work (``total`` units of ``unit``, if known)."""
    if _active is not None:
        _active.step(what, total, unit)


def advance(n: float = 1) -> None:
    """``n`` more units of the current step done."""
    if _active is not None:
        _active.advance(n)


class Progress:
    """What a command is doing, shown as a bar (terminal) or as periodic lines (otherwise)."""

    def __init__(self, command: str, *, stream: TextIO | None = None, every: float | None = None,
                 terminal: bool | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.command = command
        self.stream = stream if stream is not None else sys.stderr
        if every is None:
            every = float(os.environ.get(EVERY_ENV, "10") or 10)
        if not every > 0:
            raise ValueError(f"{EVERY_ENV} must be a number of seconds > 0, got {every!r}")
        self.every = every
        self.terminal = bool(getattr(self.stream, "isatty", lambda: False)()) if terminal is None else terminal
        self.clock = clock
        self.t0 = clock()
        self.what = "starting (imports, reading the input)"
        self.total: float | None = None
        self.unit = ""
        self.done = 0.0
        self.note = ""  # e.g. the last evaluation of a training
        self.t_step = self.t0
        self._said = False
        self._bar = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._previous: Progress | None = None

    # ------------------------------------------------------------------ reporting
    def step(self, what: str, total: float | None = None, unit: str = "") -> None:
        self.what, self.total, self.unit, self.done = what, total, unit, 0.0
        self.t_step = self.clock()
        if self.terminal:
            self._close_bar()
            from tqdm.auto import tqdm

            self._bar = tqdm(total=total, desc=what, unit=unit or "it", leave=False, file=self.stream)

    def advance(self, n: float = 1) -> None:
        self.done += n
        if self._bar is not None:
            self._bar.update(n)

    def line(self) -> str:
        """The line a non-terminal gets now."""
        now = self.clock()
        elapsed, in_step = now - self.t0, now - self.t_step
        text = f"{self.command}: {self.what}"
        if self.total:
            unit = f" {self.unit}" if self.unit else ""
            text += f" {self.done:.0f}/{self.total:.0f}{unit} ({100 * self.done / self.total:.0f} %)"
        text += f", {elapsed:.0f} s so far"
        if self.total and self.done > 0 and in_step > 0:
            left = (self.total - self.done) * in_step / self.done
            text += f", ~{left:.0f} s left in this step"
        else:
            text += ", time left not known" if not self.total else ", time left not known yet"
        return text + (f"; {self.note}" if self.note else "")

    def say(self) -> None:
        print(self.line(), file=self.stream, flush=True)
        self._said = True

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> Progress:
        global _active
        self._previous, _active = _active, self
        if not self.terminal:
            self._thread = threading.Thread(target=self._tick, name="rotor-id-progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        global _active
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            if self._said:  # after progress lines, the end in one line too
                note = f"; {self.note}" if self.note else ""
                print(f"{self.command}: {'done' if exc[0] is None else 'stopped'} after "
                      f"{self.clock() - self.t0:.0f} s{note}", file=self.stream, flush=True)
        self._close_bar()
        _active = self._previous

    def _tick(self) -> None:
        wait = self.every / 2  # the first line early: a command is not silent for 10 s
        while not self._stop.wait(wait):
            self.say()
            wait = self.every

    def _close_bar(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


class _StepBar:
    """A tqdm-like handle (``update``, ``close``) on the running command's step."""

    def __init__(self, progress: Progress) -> None:
        self.progress = progress

    def update(self, n: float = 1) -> None:
        self.progress.advance(n)

    def close(self) -> None:
        pass


def bar(what: str, total: float | None, unit: str = "", *, enabled: bool = False):
    """A progress handle for a loop of the library (``update(n)``, ``close()``).

    Under a command (:class:`Progress` active): a new step of it, in both modes.  Else a
    tqdm bar when ``enabled`` (a Python caller's ``progress=True``), or None.
    """
    if _active is not None:
        _active.step(what, total, unit)
        return _StepBar(_active)
    if enabled:
        from tqdm.auto import tqdm

        return tqdm(total=total, desc=what, unit=unit or "it", leave=False)
    return None
