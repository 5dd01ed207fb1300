"""Measurements: the model's ten columns, and the way measured rig data get into them.

- :mod:`.core` — :class:`Measurements`, the ``(m, 10)`` array of dimensionless samples the
  identifier and the diagnosis read (``t, phi, phi_dot, ..., theta_y_ddot``).
- :mod:`.files` — the reader of dimensionless measurement files (CSV, Parquet) with the
  validation that names file, line, column and value, and the Savitzky-Golay rates.
- :mod:`.rig` — the rig description (units, probes and their mounting angles, keyphasor,
  disks, which model applies), read from YAML/JSON and validated key by key.
- :mod:`.keyphasor` — once-per-revolution pulses to spin angle, speed and acceleration.
- :mod:`.probes` — proximity-probe pairs rotated into the model's axes; one plane gives
  translation (Jeffcott), two planes give the disk's tilt.
- :mod:`.vectors` — order tracking (1X, 2X, ... vectors per revolution) and the
  order-tracked vector tables condition-monitoring systems export.
- :mod:`.waveforms` — a rig's raw waveforms (keyphasor and probes) to measurements.
- :mod:`.artefacts` — what the instruments add and no rotor model holds: lines at fixed
  frequencies (mains hum) and the probe track's runout above 2X, found and taken out.
- :mod:`.drift` — the probes' slowly moving mean (the shaft's centreline on its bearings,
  thermal drift): its two-turn means, the spline through them, each plane's centreline.

Every reader of data lives here; what simulates a rig recording (the simulator's output
written as a rig would record it) is :mod:`rotor_env.rig_simulation`, beside the simulator.
"""

from .core import ANGLE_CHANNELS, COLUMNS, Measurements

__all__ = ["ANGLE_CHANNELS", "COLUMNS", "Measurements"]
