"""The run-up model's synchronous (1X) response, fitted to order-tracked vectors.

What condition-monitoring systems export for a start-up or coast-down is the 1X vector
of each probe against speed.  This package predicts those vectors from the same effect
declarations the simulator and the regression read (:mod:`rotor_env.effects`), and
fits them.

The model
---------
In the model's dimensionless time ``t' = t w_ref`` (``w_ref`` the non-rotating natural
frequency, a parameter of the fit: it carries the stiffness) the tilt — or, with
``ip = 0``, the translation (Jeffcott) — obeys ``q'' = a(q, q', phi) `` with the
declared effects' moments.  An effect whose moment does not depend on the state is a
*forcing* (unbalance, bow): the response is linear in its coefficients, which are
solved by linear least squares for every trial of the others (variable projection).
The other effects are *structural* (damping, support anisotropy, cross-coupled
stiffness): nonlinear parameters of the fit, with ``w_ref``.  Probe runout is a
measurement term: a constant vector per probe (the slow-roll vector), also linear.

A probe mounted at angle ``alpha`` (from the reference, in the direction of rotation)
reads ``p = u cos(alpha) + v sin(alpha)`` with ``u = th_y``, ``v = th_x`` (docs/PHYSICS.md
1.2: ``z = u + i v`` whirls forward as ``e^{+i phi}``); its 1X vector (``lead``
convention, :mod:`rotor_env.measurements.vectors`) is ``P = Q_u cos(alpha) + Q_v sin(alpha)``.

Quasi-steady or transient
-------------------------
*Quasi-steady*: at each speed the steady-state response
``(-W^2 I - A_q - i W A_w) Q = F`` of the model linearised at that speed.  *Transient*:
the model simulated (RK4, the simulator's compiled kernel) along the table's speed
profile — the time column gives the acceleration — and order-tracked one revolution at a
time at each row, as the data were.  At real start-up rates (e.g. 230 rpm/s through
1650 rpm with zeta = 0.02) the peak is delayed and lowered and ripples (free vibration at
the natural frequency beating against 1X) follow it: only the transient carries them.
``method="auto"`` compares the two at the first fit and keeps the quasi-steady one only
where it is within 1 % of the peak everywhere (it is faster).

The transient run is the simulator's RK4 (48 steps a turn) on one grid in seconds per fit:
where the model does not change with the speed (no gyroscopic term, no rotating effect)
its steps are one linear recursion ``x <- Phi x + G f`` written out from the RK4 stages
(:func:`_rk4_linear`, the same numbers to rounding), compiled, and the forcing's columns
are evaluated once per table; otherwise the compiled kernel integrates it.

2X
--
A table with ``_2x`` columns and a time column is fitted at 1X and 2X together (the probes
of each order side by side).  An effect whose stiffness turns with the shaft (``asymmetry``,
``breathing_crack``: *rotating*) is a nonlinear parameter like a structural one, carried
by the transient run only: a crack turns a static deflection (``static_load``, the side
load, a forcing) into 2X, which resonates where 2x the speed meets the natural frequency —
half the critical.  A 2X forcing (``misalignment``) is linear like the unbalance.  Nothing
of their physics is written here: the run integrates the declared columns and the tracker
reads its 1X and 2X, as the data's tracker did.

Critical speeds and damping ratios
----------------------------------
The eigenvalues ``lambda`` of the linearised model at speed ``W``; a critical is a speed
where a branch's whirl frequency ``|Im lambda|`` equals ``W`` (the 1x line crosses the
Campbell diagram) on a mode that whirls forward at least in part (an isotropic rotor's
backward mode is not excited by unbalance); its damping ratio is ``-Re lambda / |lambda|``.
The same eigenvalues, each signed by its whirl, are the branches of the Campbell diagram
(:func:`whirl_branches`).

The package
-----------
:mod:`.model` (the effects the model carries and how: :class:`SynchronousModel`),
:mod:`.response` (the predicted vectors, quasi-steady and transient), :mod:`.fit`
(:func:`fit_vectors`, :class:`VectorFit`) and :mod:`.criticals` (critical speeds, whirl modes,
the Campbell branches).
"""

from .criticals import critical_speeds, whirl_branches, whirl_modes
from .fit import QUASI_STEADY_TOL, W_REF_DECADES, VectorFit, extra_mode_vectors, fit_vectors
from .model import RUNOUT, SECOND_MODE, VECTOR_EFFECTS, SynchronousModel, known_effects
from .response import LEAD_IN_REVS, MAX_TRANSIENT_SAMPLES, vector_orders, vector_probe_matrix

__all__ = [
    "LEAD_IN_REVS",
    "MAX_TRANSIENT_SAMPLES",
    "QUASI_STEADY_TOL",
    "RUNOUT",
    "SECOND_MODE",
    "VECTOR_EFFECTS",
    "W_REF_DECADES",
    "SynchronousModel",
    "VectorFit",
    "critical_speeds",
    "extra_mode_vectors",
    "fit_vectors",
    "known_effects",
    "vector_orders",
    "vector_probe_matrix",
    "whirl_branches",
    "whirl_modes",
]
