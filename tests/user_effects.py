"""User effects outside the library, loaded by the diagnosis tests and the CLI tests.

``rotor-id diagnose FILE --effect tests/user_effects.py:cubic_stiffness`` loads
:func:`cubic_stiffness` as a candidate effect.  The column function follows the
convention of :mod:`rotor_env.effects` (numba-compilable plain arithmetic), so the same
function also serves the simulator that makes the test data.
"""

from __future__ import annotations


def cubic_stiffness(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    """Cubic (hardening) shaft stiffness: a restoring moment growing with |theta|^3."""
    r2 = th_x * th_x + th_y * th_y
    return (-th_y * r2,), (-th_x * r2,)
