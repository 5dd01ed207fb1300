"""Figures: every plot draws what was computed before, as statsmodels' graphics and
scikit-learn's displays do; the result objects' ``plot_*`` methods hand them their numbers.

:mod:`.field`: the views a rotordynamics engineer reads (Bode, polar, orbits, shaft
centreline, waterfall, Campbell, parameter tracks); :mod:`.diagnosis`: a diagnosis's own figures (compare, residual,
order map, autocorrelation, candidates, before and after, residual RMS against speed);
:mod:`.balance`: a balancing's runs and its correction's predicted effect.  The package
imports numpy, matplotlib and the layers below it only, never the diagnosis or balancing
that hand it their numbers.
"""

from .field import (
    bode_phases,
    by_speed,
    frequency_from_rad,
    phase_deg,
    plot_bode,
    plot_campbell,
    plot_centreline,
    plot_orbit,
    plot_parameter_tracks,
    plot_polar,
    plot_waterfall,
    speed_from_rad,
)

__all__ = ["bode_phases", "by_speed", "frequency_from_rad", "phase_deg", "plot_bode", "plot_campbell",
           "plot_centreline", "plot_orbit", "plot_parameter_tracks", "plot_polar", "plot_waterfall", "speed_from_rad"]
