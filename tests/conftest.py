"""Independent references for the identifier tests (numpy lstsq, nothing from identifier).

The helpers are exposed through the session fixture ``ref`` so that test modules do not
import this file.
"""

from __future__ import annotations

import os

# Before numpy loads its BLAS and numba its thread pool: one thread per process.  The suite
# runs in two xdist workers on two cores (and the fault suite adds a pool of two); a
# multithreaded BLAS in each oversubscribes the cores and its threads spin against each other
# (measured on the fault suite: 367 s with the default threads, 133 s with one), and so do two
# output-error fits' parallel shooting loops (two rig diagnoses side by side: 513 s and 518 s
# for what takes 30 s and 25 s alone).
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from types import SimpleNamespace  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402


def forgetting_weights(m: int, forgetting: float) -> np.ndarray:
    """``w_k = lambda^(m-1-k)`` for samples ``k = 0..m-1`` (the newest has weight 1)."""
    return forgetting ** np.arange(m - 1, -1, -1, dtype=float)


def lstsq_equilibrated(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least squares ``min ||A theta - b||`` with column equilibration.

    numpy's ``lstsq`` truncates singular values below ``eps * max(m, n) * s_max``; with
    columns scaled 1e-6..1e6 that would silently drop small-scale (but perfectly
    informative) columns.  Scaling each column to unit norm first is the same least-squares
    problem and removes that artefact from the reference.
    """
    if A.shape[1] == 0:
        return np.zeros(0)
    norms = np.linalg.norm(A, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    theta, *_ = np.linalg.lstsq(A / norms, b, rcond=None)
    return theta / norms


def nested_reference(
    X: np.ndarray,
    y: np.ndarray,
    *,
    forgetting: float = 1.0,
    prior: float = 0.0,
    keep: np.ndarray | None = None,
):
    """Energies ``J_0..J_n`` and coefficients of every nested model, by ``lstsq``.

    * weights ``w_k = lambda^(t-k)`` enter as rows scaled by ``sqrt(w_k)``;
    * ``prior = delta`` starts the factor at ``sqrt(delta) I`` of ``[X y]``, i.e. the data
      are augmented by the ``n + 1`` rows ``sqrt(delta_t) I_{n+1}`` with
      ``delta_t = lambda^t delta`` (the prior is scaled by ``sqrt(lambda)`` at every
      step like all other rows).  Order ``i`` uses the first ``i`` columns of *all* rows,
      so the prior row of ``y`` always contributes ``delta_t`` to ``J_i``;
    * ``keep`` (bool mask): columns treated as absent (coefficient 0).

    Returns ``(J, C)``: ``J`` shape ``(n+1,)``, ``C`` shape ``(n, n)`` with row ``i-1`` the
    order-``i`` coefficients, zero padded.
    """
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    m, n = X.shape
    sw = np.sqrt(forgetting_weights(m, forgetting))
    A = np.column_stack([X, y]) * sw[:, None]
    if prior > 0:
        A = np.vstack([A, np.sqrt(prior * forgetting**m) * np.eye(n + 1)])
    Xa, ya = A[:, :n], A[:, n]
    keep = np.ones(n, dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    J = np.empty(n + 1)
    C = np.zeros((n, n))
    J[0] = float(ya @ ya)
    for i in range(1, n + 1):
        cols = np.flatnonzero(keep[:i])
        theta = lstsq_equilibrated(Xa[:, cols], ya)
        r = ya - Xa[:, cols] @ theta
        J[i] = float(r @ r)
        C[i - 1, cols] = theta
    return J, C


def fitted_error(X: np.ndarray, theta: np.ndarray, theta_ref: np.ndarray, y: np.ndarray, w=None):
    """``||X (theta - theta_ref)||_w / ||y||_w``: the coefficient error measured where it
    matters (in the fitted values).  Unlike the coefficient error itself it stays small
    for ill-conditioned (near-collinear or badly scaled) columns, for which a backward
    stable solver guarantees only the fitted values, not each coefficient."""
    sw = np.ones(X.shape[0]) if w is None else np.sqrt(w)
    d = (X[:, : theta.size] @ (theta - theta_ref)) * sw
    return float(np.linalg.norm(d) / np.linalg.norm(y * sw))


@pytest.fixture(scope="session")
def ref() -> SimpleNamespace:
    return SimpleNamespace(
        forgetting_weights=forgetting_weights,
        lstsq=lstsq_equilibrated,
        nested=nested_reference,
        fitted_error=fitted_error,
    )


@pytest.fixture()
def rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


@pytest.fixture
def restore_effect_registry():
    """Restore the effect registry after a test: user effects registered by it must not
    leak into other tests (xdist may run another module's tests in this process next)."""
    from rotor_env.effects import EFFECTS

    saved = dict(EFFECTS)
    yield
    EFFECTS.clear()
    EFFECTS.update(saved)


#: modules whose tests take the longest (minutes of CPU between them): collected first, so
#: that the two xdist workers start on them and finish on the many short tests, instead of
#: one worker running a long test alone at the end (the fault suite first: one worker runs
#: it in a pool of two while the other waits for its result, see test_fault_library)
HEAVY_FIRST = ("test_fault_library", "test_measured_data", "test_report_browser", "test_coverage",
               "test_rllib", "test_diagnosis", "test_monitor_fleet", "test_fleet", "test_monitor_rig")


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    # a stable sort: the order inside each module is kept
    items.sort(key=lambda item: rank.get(item.path.stem, len(HEAVY_FIRST)))


# ------------------------------------------------------------------ rig records for the reader tests
#: the README's one-plane rig: an X-Y pair at +-45 deg in um and a keyphasor
ONE_PLANE_RIG = "keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n"


def _one_plane_run(folder, extra: dict | None = None, *, rpm=(300.0, 3000.0), rpm_per_s=300.0, noise=0.3,
                   seed=1, sample_rate=5000.0):
    """``(rig, columns, run)``: the one-plane rig written to ``folder/rig.yaml`` and a run-up of
    a rotor (damping 0.04, unbalance 0.005 at 0.6 rad, natural frequency 1650 rpm) with the
    effects whose values ``extra`` gives (``{"D": 0.03, ...}``: the effects named from them),
    as the rig records it (time in s, keyphasor, probes in um; float arrays), and the
    simulated run (:class:`rotor_env.rig_simulation.RigRun`)."""
    from rotor_env.effects import EFFECTS
    from rotor_env.measurements.rig import load_rig
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    (folder / "rig.yaml").write_text(ONE_PLANE_RIG)
    rig = load_rig(folder / "rig.yaml")
    extra = dict(extra or {})
    effects = ["stiffness", "viscous_damping", "unbalance"]
    effects += [n for n, e in EFFECTS.items() if n not in effects and any(p.name in extra for p in e.parameters)]
    params = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005, "beta": 0.6, **extra}, effects=tuple(effects))
    run = simulate_rig(rig, params, natural_rpm=1650.0, rpm_from=rpm[0], rpm_to=rpm[1], rpm_per_s=rpm_per_s,
                       noise=noise, seed=seed, sample_rate=sample_rate)
    return rig, {k: np.asarray(v, dtype=float) for k, v in run.file_columns().items()}, run


def _write_columns(path, columns: dict) -> object:
    """``columns`` as a plain CSV (header line, commas, ten significant digits); ``path``."""
    np.savetxt(path, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns),
               comments="", fmt="%.10g")
    return path


@pytest.fixture(scope="session")
def rig_records() -> SimpleNamespace:
    """``one_plane_run(folder, extra, ...)`` and ``write_csv(path, columns)`` (see above)."""
    return SimpleNamespace(one_plane_run=_one_plane_run, write_csv=_write_columns, ONE_PLANE=ONE_PLANE_RIG)
