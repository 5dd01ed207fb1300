"""Balancing by influence coefficients (rotor_env.balance, `rotor-id balance`) on simulations with truth.

The rotors are :class:`rotor_env.balance.simulate.DiskRotor` (disks on a shaft solved in the
frequency domain: linear, anisotropic, or with a clearance) and, for the model-based
unbalance, the project's own rig simulator (:func:`rotor_env.rig_simulation.simulate_rig`).
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from scipy import stats

from rotor_env.balance import (
    BalanceError,
    balance,
    balance_data,
    load_campaign,
)
from rotor_env.balance.correction import iso_grade, split_to_holes
from rotor_env.balance.runs import Campaign, Plane, group_table
from rotor_env.balance.simulate import DiskRotor, campaign_table, coverage_study, table_of, weight
from rotor_env.measurements.vectors import to_phase

RPMS = (1200.0, 1500.0, 2000.0)


def _campaign(planes, weights, **kw) -> Campaign:
    return Campaign(tuple(Plane(p, 100.0) for p in planes), "ref", weights, source="RUNS.yaml", **kw)


def _run(rotor, camp, U, *, rpms=RPMS, repeats=3, noise=1.0, seed=0):
    W = camp.trial_matrix()
    header, rows = campaign_table(rotor, rpms, U, {r: W[k] for k, r in enumerate(camp.runs)}, repeats=repeats,
                                  noise_um=noise, seed=seed)
    return balance_data(group_table(table_of(header, rows), camp), camp)


def _write(path, header, rows):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


def _polar(U):
    amp, ang = to_phase(np.atleast_1d(np.asarray(U, dtype=complex)), "lag")
    return amp, ang


def _angle_diff(a, b):
    return abs(math.remainder(a - b, 360.0))


# ------------------------------------------------------------------ truth, one and two planes
def test_one_plane_finds_the_unbalance_and_the_vibration_falls():
    rotor = DiskRotor()
    U = np.array([weight(6.0, 100.0, 30.0)])  # 600 g·mm at 30 deg (lag)
    camp = _campaign("A", {"T1": {"A": (5.0, 0.0)}})
    res = _run(rotor, camp, U, seed=1)
    d = res.to_dict()
    ref = d["runs"]["ref"]["unbalance"]["A"]
    assert abs(ref["g_mm"] - 600.0) <= 3 * ref["ci95_g_mm"]
    assert _angle_diff(ref["angle_deg"], 30.0) <= 3 * ref["ci95_deg"]
    c = d["correction"]["A"]
    assert c["mass_g"] == pytest.approx(6.0, rel=0.02)
    assert _angle_diff(c["angle_deg"], 210.0) < 2.0  # opposite the heavy spot
    # the vibration the correction leaves, applied to the simulated rotor, is what was predicted
    after = np.array([rotor.response(r, U + weight(c["mass_g"], 100.0, c["angle_deg"])) for r in RPMS])
    before = np.array([rotor.response(r, U) for r in RPMS])
    assert np.abs(after).max() < 0.05 * np.abs(before).max()
    pred = max(p["amp"] + p["ci95_amp"] for p in d["predicted_residual"])
    assert np.abs(after).max() <= pred + 1.0
    assert d["misfit"]["linear_model_trusted"]


def test_two_plane_influence_matches_lstsq_and_truth():
    rotor = DiskRotor(masses_kg=(20.0, 20.0), probes=((0, 45.0), (0, -45.0), (1, 45.0), (1, -45.0)))
    U = np.array([weight(10.0, 100.0, 60.0), weight(8.0, 100.0, 200.0)])
    camp = _campaign("AB", {"T1": {"A": (5.0, 0.0)}, "T2": {"B": (5.0, 90.0)},
                            "T3": {"A": (12.0, 180.0), "B": (3.0, 300.0)}})
    res = _run(rotor, camp, U, rpms=(1200.0, 1500.0, 2400.0, 3000.0), seed=2)
    fit = res.fit
    # an independent reference: numpy's lstsq on the weighted design, speed by speed, probe by probe
    A = np.column_stack([np.ones(4), camp.trial_matrix()])
    for s in range(4):
        for p in range(4):
            w = np.sqrt(1.0 / fit.v[:, s, p])
            ref = np.linalg.lstsq(A * w[:, None], fit.data.Y[:, s, p] * w, rcond=None)[0]
            np.testing.assert_allclose(fit.theta[s, p], ref, rtol=1e-9, atol=1e-12)
            truth = [rotor.response(fit.data.rpm[s], np.eye(2)[j])[p] for j in range(2)]
            # the truth within the estimate's own uncertainty: 2|err|^2 / var ~ chi2(2)
            var = np.real(np.diag(fit.cov_theta[s, p]))[1:]
            assert np.all(2 * np.abs(fit.H[s, p] - truth) ** 2 / var < stats.chi2.isf(1e-4, 2))
    d = res.to_dict()
    for j, name in enumerate("AB"):
        amp, ang = _polar(U[j])
        est = d["runs"]["ref"]["unbalance"][name]
        assert abs(est["g_mm"] - amp[0]) <= 3 * est["ci95_g_mm"]
        assert _angle_diff(est["angle_deg"], ang[0]) <= 3 * est["ci95_deg"]
        # every run's total unbalance is the reference's plus its trial weight
        for k, run in enumerate(camp.runs):
            a, g = _polar(U[j] + camp.trial_matrix()[k, j])
            e = d["runs"][run]["unbalance"][name]
            assert abs(e["g_mm"] - a[0]) <= 3.5 * e["ci95_g_mm"]
    assert 1.0 <= d["condition_number"] < 10
    assert d["misfit"]["linear_model_trusted"]


@pytest.mark.parametrize("planes", [1, 2])
def test_interval_coverage_over_seeds(planes):
    """95 % intervals hold the truth in a share of seeds within the binomial's 99.9 % range.

    40 seeds; the reference's unbalance (plane A) is one Bernoulli per seed.  The bigger
    study is benchmarks/balance_coverage.py (1000 seeds, quoted in docs/BALANCING.md).
    """
    n = 40
    out = coverage_study(range(100, 100 + n), planes=planes)
    lo = stats.binom.ppf(0.0005, n * planes, 0.95) / (n * planes)
    hi = stats.binom.isf(0.0005, n * planes, 0.95) / (n * planes)
    for key in ("ref_g_mm", "ref_deg"):
        assert lo <= out[key] <= hi, (key, out)
    for key in ("runs_g_mm", "runs_deg", "influence"):  # correlated within a seed: a looser band
        assert 0.85 <= out[key] <= 1.0, (key, out)
    assert out["misfit_flagged"] <= 0.1  # a linear rotor is not flagged (Bonferroni at 1 %)


def test_interval_coverage_at_low_snr_two_planes():
    """10 µm of noise, two repeats, two planes: trial weights a few standard errors out of the
    noise, where the unbalance is a ratio far from its linearisation.  The profile-likelihood
    intervals hold the truth in a share within the binomial's 99.9 % range of 95 %; the
    first-order intervals (kept in the study for comparison) covered 68-73 % here, below it.
    The bigger study: benchmarks/balance_coverage.py (400 seeds per setting, docs/BALANCING.md §4).
    """
    n = 30
    out = coverage_study(range(200, 200 + n), planes=2, noise_um=10.0, repeats=2, every_run=False)
    m = out["counts"]["ref_g_mm"]
    assert m >= 2 * n - 6  # few seeds refused (a plane the calibration cannot see)
    lo = stats.binom.ppf(0.0005, m, 0.95) / m
    hi = stats.binom.isf(0.0005, m, 0.95) / m
    for key in ("ref_g_mm", "ref_deg", "ref_g_mm_sym", "ref_deg_sym"):
        assert lo <= out[key] <= hi, (key, out)
    assert out["counts"]["ref_g_mm_low_snr"] > 0  # the seeds include weak trial weights


# ------------------------------------------------------------------ where the linear model fails
def _many_weights():
    return {"T1": {"A": (4.0, 0.0)}, "T2": {"A": (8.0, 120.0)}, "T3": {"A": (16.0, 240.0)}, "T4": {"A": (12.0, 45.0)}}


def test_clearance_rig_is_flagged_with_the_evidence_and_a_linear_twin_is_not():
    camp = _campaign("A", _many_weights())
    U = np.array([weight(6.0, 100.0, 30.0)])
    linear = _run(DiskRotor(), camp, U, seed=3).to_dict()
    assert linear["misfit"]["linear_model_trusted"]
    assert linear["misfit"]["influence"]["testable"]
    rub = _run(DiskRotor(clearance_um=60.0), camp, U, seed=3)
    d = rub.to_dict()
    assert not d["misfit"]["linear_model_trusted"]
    inf = d["misfit"]["influence"]
    assert {c["run"] for c in inf["flagged"]} >= {"T1", "T3"}
    # the evidence: the apparent influence differs between weights of different sizes
    spread = [e for e in inf["evidence"] if "apparent_influence" in e]
    assert spread
    mags = [a["amp_per_g_mm"] for a in spread[0]["apparent_influence"]]
    assert max(mags) / min(mags) > 1.3
    assert inf["explained_by"] is None  # no linear explanation removes a clearance
    assert "non-linear rotor" in rub.summary()
    assert any(r["misfit"]["flagged"] for r in d["runs"].values())


def test_anisotropic_supports_keep_the_influence_model_linear():
    """Elliptical orbits, yet each probe's 1X vector is complex-linear in the unbalance."""
    camp = _campaign("A", _many_weights())
    U = np.array([weight(6.0, 100.0, 30.0)])
    res = _run(DiskRotor(anisotropy=0.4), camp, U, seed=4)
    d = res.to_dict()
    assert d["misfit"]["linear_model_trusted"]
    est = d["runs"]["ref"]["unbalance"]["A"]
    assert abs(est["g_mm"] - 600.0) <= 3 * est["ci95_g_mm"]


def test_speed_offset_near_the_critical_is_explained():
    """Runs whose speeds differ by 1.6-3 rpm from the reference's, near the 1650 rpm critical
    (damping ratio 0.05): enough to break the plain model at 1 um of noise; the first-order
    speed correction removes the misfit (offsets of 10+ rpm need more than first order)."""
    rotor = DiskRotor()
    U = np.array([weight(6.0, 100.0, 30.0)])
    camp = _campaign("A", {**_many_weights(), "T5": {"A": (6.0, 300.0)}}, speed_tolerance_rpm=40.0)
    W = camp.trial_matrix()
    offsets = {"ref": 0.0, "T1": 3.0, "T2": -2.4, "T3": 1.6, "T4": 3.0, "T5": -2.0}
    rng = np.random.default_rng(5)
    rows = []
    for k, run in enumerate(camp.runs):
        for rpm in (1550.0, 1650.0, 1750.0):
            X = rotor.response(rpm + offsets[run], U + W[k])
            for _ in range(3):
                amp, ph = to_phase(X + (rng.normal(size=2) + 1j * rng.normal(size=2)) / math.sqrt(2), "lag")
                rows.append([run, rpm + offsets[run], amp[0], ph[0], amp[1], ph[1]])
    header = ["run", "rpm", "p1_amp", "p1_phase_deg", "p2_amp", "p2_phase_deg"]
    d = balance_data(group_table(table_of(header, rows), camp), camp).to_dict()
    inf = d["misfit"]["influence"]
    assert inf["flagged"]
    assert inf["explained_by"] == "speed_dependent_coefficient"


def test_unbalance_outside_the_plane_is_told_by_the_one_unbalance_check():
    """Two disks, weights and probes on the first only, speeds across both modes: the
    unbalance the probes see changes with speed; one unbalance per speed removes the misfit."""
    rotor = DiskRotor(masses_kg=(20.0, 20.0), probes=((0, 45.0), (0, -45.0)))
    camp = _campaign("A", {"T1": {"A": (5.0, 0.0)}, "T2": {"A": (8.0, 150.0)}})
    W = camp.trial_matrix()
    U = np.array([weight(6.0, 100.0, 30.0), weight(6.0, 100.0, 250.0)])
    header, rows = campaign_table(rotor, (1200.0, 1650.0, 2500.0, 3300.0),
                                  U, {r: np.array([W[k, 0], 0.0]) for k, r in enumerate(camp.runs)}, seed=6)
    d = balance_data(group_table(table_of(header, rows), camp), camp).to_dict()
    one = d["misfit"]["one_unbalance"]
    assert one["flagged"]
    assert one["explained_by"] == "speed_dependent_unbalance"
    assert not d["misfit"]["influence"]["flagged"]  # the influence coefficients themselves hold


# ------------------------------------------------------------------ correction helpers
def test_holes_split_adds_up_and_iso_grade():
    for ang in (0.0, 10.0, 44.9, 200.0, 359.0):
        parts = split_to_holes(7.0, ang, 8, first_hole_deg=0.0)
        total = sum(p["mass_g"] * np.exp(1j * np.radians(p["angle_deg"])) for p in parts)
        assert total == pytest.approx(7.0 * np.exp(1j * np.radians(ang)), abs=1e-9)
        assert all(p["mass_g"] >= 0 for p in parts)
    # ISO 21940-11: G = e * Omega; 100 kg at 3000 rpm, G 2.5 allows e = 2.5/314.16*1000 = 7.96 um
    g = iso_grade(795.0, 100.0, 3000.0)
    assert g["G_mm_per_s"] == pytest.approx(2.5, rel=1e-3)
    assert g["grade"] == "G 2.5"
    assert iso_grade(900.0, 100.0, 3000.0)["grade"] == "G 6.3"


# ------------------------------------------------------------------ files, CLI and bad input
RUNS_YAML = """planes: {A: {radius_mm: 100, holes: 12}}
reference: ref
runs:
  T1: {A: {mass_g: 5, angle_deg: 0}}
  T2: {A: {mass_g: 8, angle_deg: 120}}
rotor_mass_kg: 20
service_rpm: 1800
"""


@pytest.fixture
def campaign_files(tmp_path):
    camp = _campaign("A", {"T1": {"A": (5.0, 0.0)}, "T2": {"A": (8.0, 120.0)}})
    W = camp.trial_matrix()
    header, rows = campaign_table(DiskRotor(), RPMS, np.array([weight(6.0, 100.0, 30.0)]),
                                  {r: W[k] for k, r in enumerate(camp.runs)}, seed=7,
                                  probe_names=("x", "y"))
    table = _write(tmp_path / "table.csv", header, rows)
    runs = tmp_path / "runs.yaml"
    runs.write_text(RUNS_YAML)
    return table, runs, header, rows


def test_cli_json_keys_and_report(campaign_files, tmp_path, capsys):
    from rotor_env.cli import main

    table, runs, *_ = campaign_files
    report = tmp_path / "balance.html"
    assert main(["balance", str(table), "--runs", str(runs), "--json", "--report", str(report)]) == 0
    d = json.loads(capsys.readouterr().out)
    assert {"planes", "condition_number", "influence", "runs", "correction", "predicted_residual",
            "iso_21940_11", "misfit"} <= set(d)
    assert set(d["runs"]) == {"ref", "T1", "T2"}
    assert set(d["runs"]["T1"]["unbalance"]["A"]) == {"g_mm", "angle_deg", "ci95_g_mm", "ci95_deg"}
    assert {"mass_g", "angle_deg", "holes"} <= set(d["correction"]["A"])
    assert len(d["correction"]["A"]["holes"]) == 2
    assert d["iso_21940_11"]["before"]["grade"].startswith("G ")
    assert {"rpm", "probe", "plane", "amp_per_g_mm", "angle_deg", "ci95_amp_per_g_mm"} <= set(d["influence"][0])
    html = report.read_text()
    assert "<img" in html and "Correction" in html
    # never overwritten without --force
    before = report.read_bytes()
    assert main(["balance", str(table), "--runs", str(runs), "--report", str(report)]) == 2
    assert "exists" in capsys.readouterr().err
    assert report.read_bytes() == before


def test_parquet_table_with_a_numeric_run_column(campaign_files, tmp_path):
    """Parquet in, run labels written as numbers (0 the reference): read as their text."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table, runs, header, rows = campaign_files
    label = {"ref": 0, "T1": 1, "T2": 2}
    cols = {h: [r[j] for r in rows] for j, h in enumerate(header)}
    cols["run"] = [label[v] for v in cols["run"]]
    path = tmp_path / "table.parquet"
    pq.write_table(pa.table(cols), path)
    runs_num = tmp_path / "runs_num.yaml"
    runs_num.write_text(RUNS_YAML.replace("reference: ref", "reference: 0").replace("T1:", "1:").replace("T2:", "2:"))
    d_csv = balance(table, runs).to_dict()
    d_pq = balance(path, runs_num).to_dict()
    assert d_pq["correction"]["A"]["mass_g"] == pytest.approx(d_csv["correction"]["A"]["mass_g"], rel=1e-12)
    assert set(d_pq["runs"]) == {"0", "1", "2"}


def test_figures_have_units(campaign_files):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table, runs, *_ = campaign_files
    res = balance(table, runs)
    bode = res.plot_bode()
    labels = [a.get_ylabel() for a in bode.axes] + [bode.axes[-1].get_xlabel()]
    assert "1X amplitude [µm]" in labels and "speed [rpm]" in labels and "phase lag [deg]" in labels
    polar = res.plot_polar()
    assert all("[µm]" in a.get_title() for a in polar.axes)
    plt.close("all")


def _err(args, capsys):
    from rotor_env.cli import main

    assert main(args) == 2
    return capsys.readouterr().err


def test_bad_input_is_refused_by_name(campaign_files, tmp_path, capsys):
    table, runs, header, rows = campaign_files
    base = ["balance", str(table), "--runs"]

    def runs_file(text, name="r.yaml"):
        p = tmp_path / name
        p.write_text(text)
        return str(p)

    # unknown plane
    err = _err([*base, runs_file(RUNS_YAML.replace("T2: {A:", "T2: {C:"))], capsys)
    assert "runs.T2.C" in err and "unknown plane 'C'" in err
    # planes not declared
    err = _err([*base, runs_file(RUNS_YAML.replace("planes: {A: {radius_mm: 100, holes: 12}}\n", ""))], capsys)
    assert "'planes' is missing" in err
    # weight angle not declared
    err = _err([*base, runs_file(RUNS_YAML.replace("mass_g: 8, angle_deg: 120", "mass_g: 8"))], capsys)
    assert "runs.T2.A.angle_deg is missing" in err
    # a run of the runs file missing from the table
    extra = RUNS_YAML.replace("runs:\n", "runs:\n  T9: {A: {mass_g: 3, angle_deg: 10}}\n")
    err = _err([*base, runs_file(extra)], capsys)
    assert "runs.T9" in err and "no row in" in err and "table.csv" in err
    # a run in the table that the runs file does not declare: named with its line
    bad = _write(tmp_path / "bad.csv", header, [*rows, ["T7", *rows[0][1:]]])
    err = _err(["balance", str(bad), "--runs", str(runs)], capsys)
    assert f"line {len(rows) + 2}" in err and "'T7'" in err and "bad.csv" in err
    # a non-numeric amplitude: file, line, column and value
    broken = [list(r) for r in rows]
    broken[4][2] = "abc"
    bad = _write(tmp_path / "bad2.csv", header, broken)
    err = _err(["balance", str(bad), "--runs", str(runs)], capsys)
    assert "bad2.csv" in err and "line 6" in err and "x_amp" in err
    # a table without the run column
    bad = _write(tmp_path / "norun.csv", header[1:], [r[1:] for r in rows])
    err = _err(["balance", str(bad), "--runs", str(runs)], capsys)
    assert "norun.csv" in err and "no 'run' column" in err
    # copied rows are not repeats
    dup = {}
    for r in rows:  # one acquisition per run and speed, written twice
        dup.setdefault((r[0], r[1]), r)
    bad = _write(tmp_path / "copied.csv", header, [r for r in dup.values() for _ in range(2)])
    err = _err(["balance", str(bad), "--runs", str(runs)], capsys)
    assert "copied.csv" in err and "identical" in err and "rpm on probe" in err
    # a plane the calibration cannot see: a trial weight far below the scatter
    camp = _campaign("AB", {"T1": {"A": (5.0, 0.0)}, "T2": {"B": (0.001, 90.0)}})
    rotor = DiskRotor(masses_kg=(20.0, 20.0), probes=((0, 45.0), (0, -45.0), (1, 45.0), (1, -45.0)))
    with pytest.raises(BalanceError, match="plane 'B': the calibration cannot see it"):
        _run(rotor, camp, np.array([weight(6.0, 100.0, 30.0), weight(5.0, 100.0, 0.0)]), noise=2.0)
    # a plane no run weights
    with pytest.raises(BalanceError, match="plane 'B': no calibration run puts a trial weight on it"):
        _run(rotor, _campaign("AB", {"T1": {"A": (5.0, 0.0)}}), np.array([1.0 + 0j, 1.0 + 0j]))
    # planes that always move together
    with pytest.raises(BalanceError, match="cannot separate the planes"):
        _run(rotor, _campaign("AB", {"T1": {"A": (5.0, 0.0), "B": (5.0, 0.0)}}), np.array([1.0 + 0j, 1.0 + 0j]))


def test_runs_file_refuses_weights_on_the_reference(tmp_path):
    p = tmp_path / "r.yaml"
    p.write_text(RUNS_YAML.replace("runs:\n", "runs:\n  ref: {A: {mass_g: 1, angle_deg: 0}}\n"))
    with pytest.raises(BalanceError, match=r"runs\.ref: the reference run carries no trial weight"):
        load_campaign(p)


# ------------------------------------------------------------------ model-based, one run-up
def test_model_based_unbalance_agrees_with_the_influence_coefficients(tmp_path):
    """The project's rig simulator (Jeffcott, one plane): three identical sweeps, the second
    and third with trial weights.  The 1X transient fit of the reference alone (no trial
    weight) and the influence coefficients of all three give the same g·mm and angle, and
    both the truth."""
    from rotor_env.measurements.rig import load_rig
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    rig_path = tmp_path / "rig.yaml"
    rig_path.write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(rig_path)
    disk_kg, radius = 10.0, 100.0
    e_ref = 0.05 * np.exp(1j * np.radians(-40.0))  # tau = 0.05 (50 um), heavy spot 40 deg lag
    weights = {"ref": None, "T1": (2.0, 0.0), "T2": (3.0, 200.0)}
    rows = []
    for run, w in weights.items():
        e = e_ref + (0 if w is None else w[0] * radius / disk_kg / 1000.0 * np.exp(-1j * np.radians(w[1])))
        params = RotorParams(ip=0.0, values={"tau": abs(e), "beta": float(np.angle(e))},
                             effects=("stiffness", "viscous_damping", "unbalance"))
        run_ = simulate_rig(rig, params, rpm_from=1300.0, rpm_to=2100.0, rpm_per_s=230.0, noise=1.0,
                            seed=len(rows))
        tab = run_.vectors(rig, orders=(1,))
        for i in range(len(tab.speed)):
            amp, ph = to_phase(tab.vectors[1][i], "lag")
            rows.append([run, tab.t[i], tab.rpm[i], amp[0], ph[0], amp[1], ph[1]])
    table = _write(tmp_path / "sweeps.csv", ["run", "t", "rpm", "x_amp", "x_phase_deg", "y_amp", "y_phase_deg"], rows)
    runs = tmp_path / "runs.yaml"
    runs.write_text("planes: {A: {radius_mm: 100}}\nreference: ref\nruns:\n  T1: {A: {mass_g: 2, angle_deg: 0}}\n"
                    "  T2: {A: {mass_g: 3, angle_deg: 200}}\nspeed_tolerance_rpm: 3\ndisk_mass_kg: {A: 10}\n")
    res = balance(table, runs, probe_angles={"x": 45.0, "y": -45.0})
    d = res.to_dict()
    ic = d["runs"]["ref"]["unbalance"]["A"]
    mb = d["model_based"]
    truth_g_mm = 0.05 * 1e3 * disk_kg  # e in um times kg
    assert ic["g_mm"] == pytest.approx(truth_g_mm, rel=0.03)
    assert _angle_diff(ic["angle_deg"], 40.0) < 2.0
    assert mb["g_mm"] == pytest.approx(ic["g_mm"], rel=0.03)
    assert _angle_diff(mb["angle_deg"], ic["angle_deg"]) < 2.0


def test_run_up_vectors_are_real_linear_and_told_so():
    """Per-revolution vectors of a run-up (the project's rig simulator, 230 rpm/s through the
    critical): the free vibration leaks into 1X as c A + c' conj A; with five runs the
    influence check flags it and the real-linear model removes it."""
    import cmath

    from rotor_env.measurements.rig import Probe, Rig
    from rotor_env.measurements.vectors import VectorTable
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    rig = Rig(probes=(Probe("x", math.radians(45.0)), Probe("y", math.radians(-45.0))))
    camp = _campaign("A", _many_weights(), speed_tolerance_rpm=1.0)
    W = camp.trial_matrix()
    tabs = []
    for k in range(len(camp.runs)):
        u = 600 * cmath.exp(-1j * math.radians(30)) + W[k, 0]
        params = RotorParams(ip=0.0, values={"tau": abs(u) / 20e3, "beta": cmath.phase(u)},
                             effects=("stiffness", "viscous_damping", "unbalance"))
        tabs.append(simulate_rig(rig, params, rpm_from=1000.0, rpm_to=2400.0, rpm_per_s=230.0, noise=1.0,
                                 seed=7 + k).vectors(rig, orders=(1,)))
    n = len(tabs[0].speed)
    table = VectorTable(speed=np.concatenate([t.speed for t in tabs]), t=None, probes=tabs[0].probes,
                        vectors={1: np.concatenate([t.vectors[1] for t in tabs])}, source="sweeps",
                        runs=tuple(r for r in camp.runs for _ in range(n)))
    res = balance_data(group_table(table, camp), camp)
    inf = res.to_dict()["misfit"]["influence"]
    assert inf["flagged"]
    assert inf["explained_by"] == "real_linear_response"
    # the correction itself is still close: the leak is a few per cent of the response
    c = res.to_dict()["correction"]["A"]
    assert c["mass_g"] == pytest.approx(6.0, rel=0.01)
    assert _angle_diff(c["angle_deg"], 210.0) < 1.0


def test_every_angle_bound_is_where_the_profile_crosses_from_a_fresh_start():
    """Each finite angle bound of the low-SNR study's intervals (two planes, 10 um, two repeats,
    seeds 200-229) is where the profile likelihood, minimised afresh from the default start
    (no warm start), rises by the interval's critical value: within 0.2 % of it.  The profile
    is traced outward from warm starts; one point whose optimum collapsed to zero radius
    (log-radius -20) left every later point on that plateau, and seed 220's reference angle
    bound read 49.88 deg where the profile crosses at 51.27 (2.4 % of the critical value off)."""
    import rotor_env.balance.result as R
    from rotor_env.balance.influence import t_quantile

    seen = []
    orig = R.BalanceResult.profile_interval

    def recorded(self, run, j):
        iv = orig(self, run, j)
        seen.append((self, run, j, iv))
        return iv

    R.BalanceResult.profile_interval = recorded
    try:
        coverage_study(range(200, 230), planes=2, noise_um=10.0, repeats=2, every_run=False)
    finally:
        R.BalanceResult.profile_interval = orig
    checked = 0
    for res, run, j, iv in seen:
        joint = res.joint
        k = res.fit.data.runs.index(run)
        shift = complex(res.fit.W[k, j])
        crit = t_quantile(float(res.profile_dof()[j])) ** 2 / 2.0
        a = float(np.angle(joint.U[j] + shift))
        below, above = iv["deg"]
        if res.phase == "lag":  # the lag angle runs the other way
            below, above = above, below
        for sign, d in ((-1.0, below), (1.0, above)):
            if d >= 180.0 - 1e-9:
                continue  # not bounded on this side
            val, _ = joint._profile(j, shift, angle=a + sign * math.radians(d), warm=None)
            assert abs(val - joint.rss_min - crit) <= 2e-3 * crit, (run, j, sign, d)
            checked += 1
    assert checked >= 100
