"""Matplotlib rendering of a rotor episode: the orbit and the amplitude against speed.

``rgb_array`` draws on a private Agg canvas (no pyplot, no window, works headless) and
returns an ``(H, W, 3)`` uint8 array.  ``human`` draws into a pyplot figure and, with an
interactive backend, shows it and pauses ``1/render_fps``; with a non-interactive backend
(Agg, headless) it only draws (no warning, no crash).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["EpisodeHistory", "Renderer"]

_NON_INTERACTIVE = {"agg", "pdf", "ps", "svg", "pgf", "cairo", "template", "module://matplotlib_inline.backend_inline"}


class EpisodeHistory:
    """The samples of one episode needed for a picture: th_x, th_y, speed (grows per step)."""

    def __init__(self) -> None:
        self.chunks: list[np.ndarray] = []
        self.t = 0.0
        self.speed = 0.0
        self.clearance = 1.0
        self.critical_speed = float("nan")
        self.title = ""

    def clear(self, clearance: float, critical_speed: float, title: str) -> None:
        self.chunks = []
        self.t = 0.0
        self.speed = 0.0
        self.clearance = clearance
        self.critical_speed = critical_speed
        self.title = title

    def add(self, meas: np.ndarray) -> None:
        """Keep columns (phi_dot, theta_x, theta_y) of a step's measurement rows (a copy)."""
        rows = meas[np.isfinite(meas[:, 4])]
        if len(rows):
            self.chunks.append(rows[:, [2, 4, 5]].copy())
            self.t = float(rows[-1, 0])
            self.speed = float(rows[-1, 2])

    def data(self) -> np.ndarray:
        if not self.chunks:
            return np.zeros((1, 3))
        return np.concatenate(self.chunks)


class Renderer:
    """One figure with two axes, redrawn from an :class:`EpisodeHistory`."""

    def __init__(self, mode: str, fps: float, speed_max: float) -> None:
        self.mode = mode
        self.fps = fps
        self.speed_max = speed_max
        self.fig = None

    def _setup(self) -> None:
        if self.mode == "human":
            import matplotlib.pyplot as plt

            self.fig = plt.figure(figsize=(8, 4), dpi=80)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.fig = Figure(figsize=(8, 4), dpi=80)
            FigureCanvasAgg(self.fig)
        self.ax_orbit, self.ax_amp = self.fig.subplots(1, 2)
        (self.orbit,) = self.ax_orbit.plot([], [], lw=0.6, color="tab:blue")
        (self.dot,) = self.ax_orbit.plot([], [], "o", color="tab:red", ms=4)
        (self.amp,) = self.ax_amp.plot([], [], lw=0.8, color="tab:blue")
        self.clear_circle = self.ax_orbit.plot([], [], "--", color="gray", lw=0.8)[0]
        self.clear_line = self.ax_amp.axhline(1.0, ls="--", color="gray", lw=0.8)
        self.crit_line = self.ax_amp.axvline(1.0, ls=":", color="tab:orange", lw=0.8)
        self.ax_orbit.set_xlabel("theta_x")
        self.ax_orbit.set_ylabel("theta_y")
        self.ax_orbit.set_aspect("equal")
        self.ax_amp.set_xlabel("speed phi_dot")
        self.ax_amp.set_ylabel("|theta|")
        self.ax_amp.set_xlim(0.0, self.speed_max)
        self.fig.tight_layout(rect=(0, 0, 1, 0.92))

    def draw(self, hist: EpisodeHistory) -> np.ndarray | None:
        if self.fig is None:
            self._setup()
        d = hist.data()
        cl = hist.clearance
        self.orbit.set_data(d[:, 1], d[:, 2])
        self.dot.set_data(d[-1:, 1], d[-1:, 2])
        ang = np.linspace(0.0, 2.0 * math.pi, 100)
        self.clear_circle.set_data(cl * np.cos(ang), cl * np.sin(ang))
        self.ax_orbit.set_xlim(-1.1 * cl, 1.1 * cl)
        self.ax_orbit.set_ylim(-1.1 * cl, 1.1 * cl)
        self.amp.set_data(d[:, 0], np.hypot(d[:, 1], d[:, 2]))
        self.ax_amp.set_ylim(0.0, 1.1 * cl)
        self.clear_line.set_ydata([cl, cl])
        if math.isfinite(hist.critical_speed):
            self.crit_line.set_xdata([hist.critical_speed, hist.critical_speed])
        self.fig.suptitle(f"{hist.title}   t = {hist.t:.1f}   speed = {hist.speed:.3f}", fontsize=10)
        if self.mode == "human":
            import matplotlib
            import matplotlib.pyplot as plt

            self.fig.canvas.draw()
            if matplotlib.get_backend().lower() not in _NON_INTERACTIVE:
                plt.show(block=False)
                plt.pause(1.0 / self.fps)
            return None
        self.fig.canvas.draw()
        return np.asarray(self.fig.canvas.buffer_rgba())[:, :, :3].copy()

    def close(self) -> None:
        if self.fig is not None and self.mode == "human":
            import matplotlib.pyplot as plt

            plt.close(self.fig)
        self.fig = None
