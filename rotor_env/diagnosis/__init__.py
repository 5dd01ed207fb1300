"""Diagnosis: compare a model with measurements, find where it fails and what is missing.

Workflow (PHYSICS.md section 7)::

    result = diagnose(meas, model=["unbalance", "viscous_damping"], ip=0.3)
    print(result.summary())            # what is missing, before/after numbers
    result.plot_compare()              # measured vs model response against speed
    result.report("report.html")       # everything, self-contained

**Compare.**  A model is fitted to the *equation error* (batch least squares on the
regression of :mod:`rotor_env.regression`, both equations stacked) and judged by
(a) the residual RMS and R² of that regression and (b) the *output error* of a
free-run simulation of the identified model, driven by the measured spin profile
from the measured initial state: NRMSE fit % of ``theta_x``, ``theta_y`` (MATLAB's
``compare``: ``100 (1 - |y - y_hat| / |y - mean(y)|)``), overall and per speed band.

**Informative window.**  While the disk sticks to the shaft (dry friction, low
speed) or the rotor barely moves, the data carry no information on the dynamics and
bias the damping terms.  The analysis uses the samples from the first time the
amplitude ``|theta|`` exceeds ``window_fraction`` (default 10 %) of its peak.

**Which effect is missing.**  Every candidate effect not in the model is ranked by
the partial F of *adding* it (the restricted model is the current one, so a
candidate such as ``stiffness`` that replaces a known coefficient is tested the same
way).  Forward selection adds the best candidate while both hold:

1. *significant*: ``p < alpha / n`` with ``n`` the number of candidates in that round
   (Bonferroni), and
2. *practically relevant*: the free-run fit improves by at least ``min_fit_gain``
   percentage points (default 2), or the equation-error energy falls by at least
   ``min_energy_drop`` (default 5 %) while the free-run fit does not get worse by
   ``min_fit_gain`` or more.

Rule 2 keeps data that only approximately follow the model (another simulator, a
rig) from raising false alarms on tiny, statistically significant improvements,
while a real effect moves the free-run fit by far more (PHYSICS.md: the equation
error may move by a few % only, the output error plainly).

**Onset.**  For every effect added, a change-point scan splits its coefficient at
time ``t_c`` (before/after) over a grid and takes the ``t_c`` of least residual
energy; the effect is reported as appearing at ``t_c`` when the split is
significant (Bonferroni over the grid) and removes at least 5 % of the energy.

**Scanned parameters.**  An effect whose parameter enters its columns non-linearly
(the rub's clearance: :attr:`rotor_env.effects.Parameter.scan_points`) is fitted at
every value of that parameter's grid where it acts on part of the record (not on
almost all of it: then it is a stiffness change to these data), the value of least
residual energy is kept and reported (``candidates[*].scan``, and in the parameters),
and its test pays a Bonferroni factor of the values tried, as the onset scan does.
"""

from ..measurements.vectors import order_map
from .candidates import Candidate
from .compare import Comparison, compare
from .model import DEFAULT_MODEL, LIBRARY_CANDIDATES, Model, effect_from_function, load_user_effect
from .orders import autocorrelation, complex_rows, failing_windows, noise_floor
from .result import Diagnosis
from .workflow import diagnose, fit

__all__ = [
    "DEFAULT_MODEL",
    "LIBRARY_CANDIDATES",
    "Candidate",
    "Comparison",
    "Diagnosis",
    "Model",
    "autocorrelation",
    "compare",
    "complex_rows",
    "diagnose",
    "effect_from_function",
    "failing_windows",
    "fit",
    "load_user_effect",
    "noise_floor",
    "order_map",
]
