"""``rotor-id diagnose`` and ``rotor-id fit``, run in-process through ``rotor_env.cli.main``.

The measurement files are simulated once per module: the linear Jeffcott rotor with a
hidden asymmetry (D = 0.03), and one with a cubic stiffness the library lacks (the
user effect of ``tests/user_effects.py``); noise std 5e-4 on the six inclination
channels.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import pytest

from rotor_env.cli import main
from rotor_env.effects import EFFECTS, PHYSICAL_EFFECTS
from rotor_env.params import RotorParams
from rotor_env.simulator import simulate

ROOT = Path(__file__).resolve().parent.parent
JEFFCOTT = RotorParams().replace(D=0.0, k30=0.0, k21=0.0, k12=0.0, k03=0.0, h=0.0)
CANDIDATE_KEYS = {"effect", "F", "log10_p", "rms_after", "fit_percent_after"}


# user effects registered here must not leak into other tests (conftest.py)
pytestmark = pytest.mark.usefixtures("restore_effect_registry")


@pytest.fixture(scope="module")
def asym_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "asym.csv"
    simulate(JEFFCOTT.replace(D=0.03), noise=5e-4, seed=11).to_file(path)
    return path


@pytest.fixture(scope="module")
def asym_json(asym_file) -> tuple[str, dict]:
    """The default diagnosis of ``asym_file`` (stdout, parsed), run once per module."""
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(["diagnose", str(asym_file), "--json"])
    assert rc == 0
    return buf.getvalue(), json.loads(buf.getvalue())


@pytest.fixture(scope="module")
def cubic_file(tmp_path_factory) -> Path:
    from rotor_env.diagnosis import load_user_effect

    saved = dict(EFFECTS)
    try:
        load_user_effect(f"{ROOT / 'tests' / 'user_effects.py'}:cubic_stiffness")
        params = RotorParams(
            effects=(*PHYSICAL_EFFECTS, "cubic_stiffness"),
            values={"D": 0.0, "k30": 0.0, "k21": 0.0, "k12": 0.0, "k03": 0.0, "h": 0.0,
                    "cubic_stiffness": 1.0},
        )
        path = tmp_path_factory.mktemp("cli") / "cubic.csv"
        simulate(params, noise=5e-4, seed=12).to_file(path)
        return path
    finally:
        EFFECTS.clear()
        EFFECTS.update(saved)


# ---------------------------------------------------------------- diagnose --json
def test_diagnose_json_is_one_object_with_the_fields(asym_json):
    text, out = asym_json
    assert text.strip().count("\n") == 0, "--json prints exactly one line: one JSON object"
    assert isinstance(out, dict)
    assert out["start_model"] == ["unbalance", "viscous_damping"]  # the --model default
    assert out["model"] == ["unbalance", "viscous_damping", "asymmetry"]
    assert out["missing"] == ["asymmetry"]
    assert out["onset"] == {"asymmetry": None}
    cands = out["candidates"]
    assert isinstance(cands, list) and cands
    for c in cands:
        assert CANDIDATE_KEYS <= set(c)
    # the open crack, or the breathing law that contains it: both tests stand below log10 p =
    # -80000, where which leads is rounding (the ip read with every crack law free moves it)
    assert cands[0]["effect"] in ("asymmetry", "breathing_crack")
    assert next(c for c in cands if c["effect"] == "asymmetry")["log10_p"] < -1000
    assert [c["log10_p"] for c in cands] == sorted(c["log10_p"] for c in cands)  # best first
    from rotor_env.diagnosis import LIBRARY_CANDIDATES

    assert {c["effect"] for c in cands} == set(LIBRARY_CANDIDATES) - {"unbalance", "viscous_damping"}
    for key in ("rms_before", "rms_after", "fit_percent_before", "fit_percent_after"):
        assert isinstance(out[key], float)
    assert out["rms_after"] < out["rms_before"]
    assert out["fit_percent_after"] > out["fit_percent_before"]
    coef = out["coefficients"]
    assert set(coef) == {"tau_cos_beta", "tau_sin_beta", "c", "D"}
    assert coef["D"] == pytest.approx(0.03, rel=0.05)


def test_diagnose_explicit_model(asym_file, capsys):
    rc = main(["diagnose", str(asym_file), "--json", "--model", "unbalance, viscous_damping,asymmetry"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["start_model"] == ["unbalance", "viscous_damping", "asymmetry"]
    assert out["missing"] == []
    assert "asymmetry" not in {c["effect"] for c in out["candidates"]}


@pytest.mark.parametrize("cmd", ["diagnose", "fit"])
def test_unknown_model_name_exits_2_with_known_names(asym_file, capsys, cmd):
    rc = main([cmd, str(asym_file), "--model", "unbalance,crack_of_doom"])
    assert rc == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    assert "crack_of_doom" in cap.err
    for known in ("asymmetry", "nonlinear_stiffness", "structural_damping", "viscous_damping", "unbalance"):
        assert known in cap.err


def test_bad_inputs_exit_2(tmp_path, asym_file, capsys):
    assert main(["diagnose", str(tmp_path / "absent.csv"), "--json"]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["diagnose", str(asym_file), "--effect", "nocolon"]) == 2
    assert "MODULE:NAME" in capsys.readouterr().err
    assert main(["diagnose", str(asym_file), "--model", " , "]) == 2
    assert "at least one effect" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # --model is required for fit
        main(["fit", str(asym_file)])
    assert exc.value.code == 2


def test_diagnose_with_user_effect(cubic_file, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)  # the spec is relative to the working directory, as typed
    rc = main(["diagnose", str(cubic_file), "--effect", "tests/user_effects.py:cubic_stiffness", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["missing"] == ["cubic_stiffness"]
    assert out["candidates"][0]["effect"] == "cubic_stiffness"
    assert out["coefficients"]["cubic_stiffness"] == pytest.approx(1.0, rel=0.05)
    assert out["rms_after"] < out["rms_before"]
    assert out["fit_percent_after"] > out["fit_percent_before"]


# ---------------------------------------------------------------- fit
def test_fit_json(asym_file, capsys):
    rc = main(["fit", str(asym_file), "--model", "unbalance,viscous_damping,asymmetry", "--json"])
    assert rc == 0
    text = capsys.readouterr().out
    assert text.strip().count("\n") == 0
    out = json.loads(text)
    assert out["model"] == ["unbalance", "viscous_damping", "asymmetry"]
    assert set(out["coefficients"]) == {"tau_cos_beta", "tau_sin_beta", "c", "D"}
    assert out["coefficients"]["D"] == pytest.approx(0.03, rel=0.05)
    assert out["coefficients"]["c"] == pytest.approx(0.03, rel=0.05)
    assert isinstance(out["rms"], float) and out["rms"] > 0
    assert 95.0 < out["fit_percent"] <= 100.0
    assert set(out["significance"]) == {"unbalance", "viscous_damping", "asymmetry"}
    for v in out["significance"].values():
        assert {"F", "log10_p", "significant", "testable"} <= set(v)
        assert v["significant"] is True
    # the text form
    rc = main(["fit", str(asym_file), "--model", "unbalance,viscous_damping"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "effects tested last" in text and "free-run fit" in text


# ---------------------------------------------------------------- report and figures
def test_report_refuses_to_overwrite_without_force(asym_file, tmp_path, capsys):
    report = tmp_path / "r.html"
    report.write_text("keep me")
    rc = main(["diagnose", str(asym_file), "--report", str(report)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "--force" in err and str(report) in err
    assert report.read_text() == "keep me"
    figs = tmp_path / "figs"
    figs.mkdir()
    (figs / "old.png").write_bytes(b"x")
    assert main(["diagnose", str(asym_file), "--figures", str(figs)]) == 2
    assert "--force" in capsys.readouterr().err


def test_report_and_figures_written(asym_file, tmp_path, capsys):
    report = tmp_path / "r.html"
    report.write_text("old")
    figs = tmp_path / "figs"  # does not exist yet: created
    rc = main(["diagnose", str(asym_file), "--report", str(report), "--figures", str(figs), "--force"])
    assert rc == 0
    out = capsys.readouterr().out  # the text summary (no --json)
    assert "report written to" in out and "figures written to" in out
    assert "missing effects, in the order added:\n  + asymmetry  (present throughout)" in out
    assert "final model: unbalance, viscous_damping, asymmetry" in out
    html = report.read_text()
    assert html.startswith("<!DOCTYPE html>") and "asymmetry" in html
    pngs = sorted(p.name for p in figs.glob("*.png"))
    from rotor_env.diagnosis import Diagnosis

    assert pngs == sorted(f"{n}.png" for n in Diagnosis.FIGURES)
    for p in figs.glob("*.png"):
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
