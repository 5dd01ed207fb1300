"""The drawing package (issue 23): data in, figure out, units on every axis, nothing from above.

Every plot function of :mod:`rotor_env.plots.diagnosis` and :mod:`rotor_env.plots.balance`
is called on small synthetic arrays: it returns a figure whose axes are labelled with their
units and hold the curves it was given; the results' thin ``plot_*`` methods of the
output-error and the 1X-vector diagnoses are called on stand-ins holding only the numbers
they read.  And ``rotor_env.plots`` imports neither the diagnosis nor the balancing (read
from the source with :mod:`ast`, and checked in a fresh interpreter's ``sys.modules``).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure

from rotor_env.plots import balance as pb
from rotor_env.plots import diagnosis as pd

ROOT = Path(__file__).resolve().parent.parent
PLOTS = ROOT / "rotor_env" / "plots"


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _units(ax, *units: str) -> None:
    """Both labels of ``ax`` are set, and each names one of ``units``."""
    for label in (ax.get_xlabel(), ax.get_ylabel()):
        assert label, f"an unlabelled axis on {ax.get_title()!r}"
        assert any(u in label for u in units), f"no unit of {units} in {label!r}"


def _lines(ax) -> list:
    """The data curves of ``ax`` (not the reference lines drawn with axhline/axvline)."""
    return [ln for ln in ax.lines if len(np.atleast_1d(ln.get_xdata())) > 2]


# ------------------------------------------------------------------ the diagnosis's figures
def test_compare_draws_measured_models_and_errors_with_units():
    speed = np.linspace(100.0, 3000.0, 200)
    amp = 1.0 / np.abs(1.0 - (speed / 1500.0) ** 2 + 0.1j * speed / 1500.0)
    models = {"starting model": (speed, 0.9 * amp), "final model": (speed, amp)}
    errors = {"starting model": 0.1 * amp, "final model": 0.01 * amp}
    fig = pd.plot_compare(speed, amp, models, errors=errors, zoom=(1300.0, 1700.0), speed_unit="rpm",
                          amp_unit="µm")
    assert isinstance(fig, Figure)
    top, bottom = fig.axes[:2]
    assert len(_lines(top)) == 3 and len(_lines(bottom)) == 2
    assert top.get_ylabel().endswith("(µm)")
    _units(bottom, "rpm", "µm")
    assert bottom.get_xlabel() == "spin speed (rpm)"
    assert len(top.child_axes) == 1  # the zoom on the critical
    # on one axes: the top panel only, the speed on its x axis
    own, ax = plt.subplots()
    assert pd.plot_compare(speed, amp, models, speed_unit="rpm", amp_unit="µm", ax=ax) is own
    _units(ax, "rpm", "µm")
    assert len(_lines(ax)) == 3


def test_residual_in_time_with_its_speed_axis():
    t = np.linspace(0.0, 10.0, 500)
    r = 1e-3 * np.sin(7 * t)
    fig = pd.plot_residual(t, r, 4e-4, windows=[(2.0, 3.0)], speed_axis=(t, 300.0 * t), which="after",
                           model=("unbalance",), rms=7e-4, time_unit="s", speed_unit="rpm")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "t (s)" and "dimensionless" in ax.get_ylabel()
    assert len(_lines(ax)) == 1 and len(ax.patches) == 1  # the residual and one shaded window
    assert ax.child_axes[0].get_xlabel() == "speed (rpm)"
    # a speed that is not monotone in time: no speed axis
    fig = pd.plot_residual(t, r, 4e-4, speed_axis=(t, np.sin(t)))
    assert fig.axes[0].child_axes == []


def test_order_map_expected_and_mirrored_lines():
    speeds = np.array([3.0, 1.0, 2.0])  # not monotone: drawn by speed
    orders = np.arange(-4, 5, dtype=float)
    amp = np.abs(np.random.default_rng(1).normal(size=(3, orders.size)))
    fig = pd.plot_order_map(speeds, orders, amp,
                            expected=[("asymmetry", (2.0, -2.0), "added"), ("rub", (), "lookalike")],
                            mirrored=[("asymmetry", 2, np.array([1.0, 2.0, 3.0]), np.array([1.2, 1.4, 1.6]))],
                            speed_unit="rpm")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "speed (rpm)" and "order" in ax.get_xlabel()
    labels = [t.get_text() for t in ax.get_legend().texts]
    assert labels == ["asymmetry", "rub (lookalike): no order line", "asymmetry: the free whirl ω mirrored to 2x − ω/Ω"]
    assert [c.get_label() for c in fig.axes if c.get_label() == "<colorbar>"]


def test_autocorrelation_candidates_and_before_after():
    ac = np.exp(-np.arange(50) / 5.0)
    fig = pd.plot_autocorrelation(np.arange(50) * 0.01, ac, 0.05, time_unit="s")
    _units(fig.axes[0], "s", "normalised")
    assert len(_lines(fig.axes[0])) == 1
    fig = pd.plot_candidates(["a", "b", "c"], [-12.0, -0.5, 0.0], [True, False, False], 3.0)
    ax = fig.axes[0]
    assert len(ax.patches) == 3 and ax.patches[0].get_width() == pytest.approx(12.0)
    assert "dimensionless" in ax.get_xlabel()
    t = np.linspace(0.0, 100.0, 400)
    residuals = {"t": t, "before": np.sin(t), "after": 0.1 * np.sin(t), "rms_before": 0.7, "rms_after": 0.07,
                 "noise_floor": 0.05, "time_unit": "s"}
    fig = pd.plot_before_after(["start", "+ asymmetry"], [40.0, 99.0], [0.7, 0.07], residuals=residuals)
    bars, res, twin = fig.axes[:3]  # the twin of the bars' axes comes after the figure's own
    assert bars.get_ylabel() == "free-run fit (%)" and "dimensionless" in twin.get_ylabel()
    assert len(bars.patches) == 2 and len(twin.patches) == 2
    _units(res, "s", "dimensionless")
    assert len(_lines(res)) == 2 and len(res.child_axes) == 1  # both residuals and the zoom
    assert "noise floor" in [t.get_text() for t in res.get_legend().texts][2]


def test_residual_by_speed_and_orbit_radius():
    rpm = np.linspace(500.0, 3000.0, 40)
    curves = {"start model": (rpm, np.full(40, 3.0)), "final model": (rpm, np.full(40, 1.1))}
    fig = pd.plot_residual_by_speed(curves, 1.0, quantity="1X residual RMS", amp_unit="µm", floor_ratio=1.5,
                                    marks=[1500.0])
    ax = fig.axes[0]
    assert ax.get_xlabel() == "speed [rpm]" and ax.get_ylabel() == "1X residual RMS [µm]"
    assert len(_lines(ax)) == 2 and len(ax.lines) == 5  # two curves, the floor, 1.5x the floor, a critical
    fig = pd.plot_residual_by_speed(curves, 1.0, log=True)
    assert fig.axes[0].get_yscale() == "log"
    fig = pd.plot_orbit_radius(rpm, np.full(40, 2.0), np.full(40, 2.1), amp_unit="µm")
    _units(fig.axes[0], "rpm", "µm")
    assert len(_lines(fig.axes[0])) == 2


def test_speed_axis_functions_still_importable_from_the_report():
    from rotor_env.diagnosis.report import speed_axis_functions

    assert speed_axis_functions is pd.speed_axis_functions


# ------------------------------------------------------------------ the balancing's figures
def _campaign(S=5, P=2):
    rpm = np.linspace(1000.0, 3000.0, S)
    X0 = (10.0 + np.arange(S)[:, None]) * np.exp(1j * np.linspace(0.3, 1.2, P))[None, :] * np.ones((S, P))
    runs = {"ref": X0, "T1": X0 + 3.0, "T2": X0 - 3.0j}
    return rpm, X0, runs


def test_correction_polar_one_panel_per_probe():
    rpm, X0, runs = _campaign()
    arrows = {"A": (X0[2], X0[2] + 3.0), "B": (X0[2], X0[2] - 3.0j)}
    fig = pb.plot_correction_polar(["x1", "y1"], runs, 0.1 * X0, arrows, arrow_rpm=2000.0, amp_unit="µm")
    assert len(fig.axes) == 2
    for ax in fig.axes:
        assert ax.name == "polar" and "[µm]" in ax.get_title() and "[deg]" in ax.get_title()
        assert len(ax.lines) == 4  # three runs and the predicted after
        assert [t.get_text() for t in ax.texts if "H·W" in t.get_text()] == [" H·W A", " H·W B"]
        assert len(ax.texts) == 4  # and one arrow per plane
    assert "2000 rpm" in fig._suptitle.get_text()
    with pytest.raises(ValueError, match="one polar axes per probe"):
        pb.plot_correction_polar(["x1", "y1"], runs, X0, ax=plt.subplots(subplot_kw={"projection": "polar"})[1])


def test_correction_bode_before_and_after_with_units():
    rpm, X0, _ = _campaign()
    fig = pb.plot_correction_bode(rpm, ["x1", "y1"], X0, 0.1 * X0, np.full(X0.shape, 0.5), phase="lag",
                                  amp_unit="µm")
    amp, ph = fig.axes
    assert amp.get_ylabel() == "1X amplitude [µm]" and ph.get_ylabel() == "phase lag [deg]"
    assert ph.get_xlabel() == "speed [rpm]" and ph.get_ylim() == (0.0, 360.0)
    assert len(amp.lines) >= 4 and len(ph.lines) == 4  # before and after per probe
    own, axes = plt.subplots(2, 1)
    assert pb.plot_correction_bode(rpm, ["x1", "y1"], X0, X0, phase="lead", ax=axes) is own
    assert axes[1].get_ylim() == (-180.0, 180.0)


# ------------------------------------------------------------------ the results' thin methods
def test_vector_diagnosis_residual_figure_from_its_numbers():
    from rotor_env.diagnosis.from_vectors import VectorDiagnosis

    rpm = np.linspace(500.0, 3000.0, 30)

    def fit(scale, names):
        return SimpleNamespace(residual=scale * np.ones((30, 2), complex), model=SimpleNamespace(names=names),
                               criticals=[{"rpm": 1500.0}])

    stub = SimpleNamespace(table=SimpleNamespace(rpm=rpm, amp_unit="um"), before=fit(3.0, ["unbalance"]),
                           after=fit(1.0, ["unbalance", "bow"]), noise_floor=1.0)
    fig = VectorDiagnosis.plot_residual(stub)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "speed [rpm]" and ax.get_ylabel() == "1X residual RMS [µm]"
    assert [ln.get_label() for ln in _lines(ax)] == ["start model (unbalance)", "final model (unbalance, bow)"]
    np.testing.assert_allclose(_lines(ax)[0].get_ydata(), 3.0)


def test_output_error_figures_from_their_numbers():
    from rotor_env.diagnosis import oe_diagnosis

    n = 60
    grid = SimpleNamespace(phid=np.linspace(0.5, 2.0, n), y=np.ones((n, 2)),
                           segments=np.array([[0, 29], [30, 59]]))

    def fit(level):
        return SimpleNamespace(grid=grid, residual=np.full(n, level), prediction=np.ones((n, 2)))

    diag = SimpleNamespace(before=fit(3.0), after=fit(1.0), unit_scale=10.0, probe_factor=1.0, noise_floor=0.1,
                           unit="µm")
    fig = oe_diagnosis.plot_residual(diag, 60.0, "speed [rpm]")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "speed [rpm]" and ax.get_ylabel() == "output-error RMS [µm]"
    assert ax.get_yscale() == "log" and len(ax.lines) == 3  # before, after, the floor
    np.testing.assert_allclose(ax.lines[0].get_ydata(), 30.0)
    fig = oe_diagnosis.plot_response(diag)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "speed (model units)" and ax.get_ylabel() == "orbit radius [µm]"
    np.testing.assert_allclose(ax.lines[0].get_ydata(), 10.0 * np.sqrt(2.0))


# ------------------------------------------------------------------ nothing from above
def _imports(path: Path) -> set[str]:
    """Every module named by an import of ``path`` (relative imports resolved), lazy ones too."""
    parts = ["rotor_env", "plots"]  # the package of every file there (__init__ included)
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = parts[: len(parts) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            found |= {mod} | ({f"{mod}.{a.name}" for a in node.names} if node.level else set())
    return found


def test_plots_import_neither_the_diagnosis_nor_the_balancing():
    files = sorted(PLOTS.glob("*.py"))
    assert {"field.py", "diagnosis.py", "balance.py"} <= {f.name for f in files}
    for f in files:
        for mod in _imports(f):
            top = mod.split(".")[0]
            assert top in {"__future__", "collections", "math", "numpy", "matplotlib", "rotor_env"}, (f.name, mod)
            if top == "rotor_env":
                assert mod.startswith(("rotor_env.plots", "rotor_env.measurements")), (f.name, mod)
    # in a fresh interpreter, past the package facade (rotor_env/__init__.py imports the
    # diagnosis for its users): a bare rotor_env package, then every module of plots
    code = ("import sys, types; pkg = types.ModuleType('rotor_env'); "
            f"pkg.__path__ = [{str(ROOT / 'rotor_env')!r}]; sys.modules['rotor_env'] = pkg; "
            "import rotor_env.plots, rotor_env.plots.field, rotor_env.plots.diagnosis, rotor_env.plots.balance; "
            "print(sorted(m for m in sys.modules if m.startswith('rotor_env.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         env={"MPLBACKEND": "Agg", "PATH": "", "OMP_NUM_THREADS": "1"})
    assert out.returncode == 0, out.stderr
    loaded = ast.literal_eval(out.stdout.strip().splitlines()[-1])
    assert "rotor_env.plots.diagnosis" in loaded and "rotor_env.plots.balance" in loaded
    assert not [m for m in loaded if m.startswith(("rotor_env.diagnosis", "rotor_env.balance"))], loaded
