"""The shaft's spin between two samples, as the shooting kernels integrate through it."""

from __future__ import annotations

from numba import njit

__all__ = ["spin_between"]


@njit(cache=True)
def spin_between(angle: float, speed: float, acceleration: float, tau: float) -> tuple[float, float]:
    """The shaft's angle and speed ``tau`` after a point where they are ``angle`` and ``speed``,
    at constant ``acceleration``: the spin between two samples (the measured speed's change over
    the step), where every RK4 stage of the output-error kernels evaluates its moments."""
    return angle + speed * tau + 0.5 * acceleration * tau * tau, speed + acceleration * tau
