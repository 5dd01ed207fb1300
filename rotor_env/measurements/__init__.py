"""Measurements: the model's ten columns, and the way measured rig data get into them.

- :mod:`.core` — :class:`Measurements`, the ``(m, 10)`` array of dimensionless samples the
  identifier and the diagnosis read (``t, phi, phi_dot, ..., theta_y_ddot``).
- :mod:`.rig` — the rig description (units, probes and their mounting angles, keyphasor,
  disks, which model applies), read from YAML/JSON and validated key by key.
- :mod:`.keyphasor` — once-per-revolution pulses to spin angle, speed and acceleration.
- :mod:`.probes` — proximity-probe pairs rotated into the model's axes; one plane gives
  translation (Jeffcott), two planes give the disk's tilt.
- :mod:`.vectors` — order tracking (1X, 2X, ... vectors per revolution) and the
  order-tracked vector tables condition-monitoring systems export.
"""

from .core import ANGLE_CHANNELS, COLUMNS, Measurements

__all__ = ["ANGLE_CHANNELS", "COLUMNS", "Measurements"]
