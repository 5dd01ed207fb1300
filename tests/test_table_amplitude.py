"""A table's amplitude measure: zero to peak (the package's ``|X|``), peak to peak (what
proximity-probe systems display, API 670), or RMS -- read as the user says, every size the
diagnosis and the balancing report then zero to peak (``--amp-unit "mil pp"``)."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from rotor_env.balance import balance
from rotor_env.balance.runs import Campaign, Plane
from rotor_env.balance.simulate import DiskRotor, campaign_table, weight
from rotor_env.cli import main
from rotor_env.diagnosis.from_vectors import diagnose_vectors
from rotor_env.measurements.vectors import VectorTableError, amplitude_unit, load_vector_table


@pytest.mark.parametrize(("text", "expected"), [
    ("um", ("um", "pk")), ("mil pp", ("mil", "pp")), ("um-pp", ("um", "pp")), ("MM_RMS", ("mm", "rms")),
    ("µm pp", ("µm", "pp")), ("m 0-pk", ("m", "pk")), (" mil  PP ", ("mil", "pp")), ("um pk", ("um", "pk")),
])
def test_amplitude_units_are_read_with_their_measure(text, expected):
    assert amplitude_unit(text) == expected


@pytest.mark.parametrize("text", ["", "inch", "mil p-p-p", "pp", "um pp rms", "V pp"])
def test_an_unknown_amplitude_unit_names_what_is_accepted(text):
    with pytest.raises(VectorTableError, match=r"expected one of um, µm, mil, mm, m.*pk, pp, rms"):
        amplitude_unit(text)


def _rewrite(src, dst, factor: float) -> None:
    """``src``'s table with every amplitude column times ``factor`` (phases and speeds as they are)."""
    with open(src, newline="") as fh:
        rows = list(csv.reader(fh))
    head = rows[0]
    amp = [j for j, h in enumerate(head) if "_amp" in h or h == "amp"]
    with open(dst, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        for r in rows[1:]:
            w.writerow([repr(float(v) * factor) if j in amp else v for j, v in enumerate(r)])


@pytest.fixture(scope="module")
def tables(tmp_path_factory, rig_records):
    """A bowed rotor's 1X table (a 4 um bow, 5 um unbalance; 0.3 um noise) written zero to peak,
    peak to peak and RMS."""
    folder = tmp_path_factory.mktemp("tables")
    rig, _, run = rig_records.one_plane_run(folder, {"bow": 0.004, "bow_phase": 0.0}, rpm_per_s=230.0,
                                            sample_rate=3000.0)
    run.vectors(rig, (1,)).to_csv(folder / "pk.csv")
    _rewrite(folder / "pk.csv", folder / "pp.csv", 2.0)
    _rewrite(folder / "pk.csv", folder / "rms.csv", 1.0 / math.sqrt(2.0))
    return folder


def test_peak_to_peak_and_rms_tables_hold_the_same_vectors(tables):
    angles = {"x": 45.0, "y": -45.0}
    pk = load_vector_table(tables / "pk.csv", angles=angles)
    for name, unit in (("pp", "um pp"), ("rms", "um rms")):
        other = load_vector_table(tables / f"{name}.csv", amp_unit=unit, angles=angles)
        assert other.amp_unit == "um"
        np.testing.assert_allclose(other.vectors[1], pk.vectors[1], rtol=1e-12)
        phrase = {"pp": "peak to peak", "rms": "RMS"}[name]
        assert any(phrase in n and "zero to peak" in n for n in other.notes), other.notes
    assert not any("zero to peak" in n for n in pk.notes)


def test_the_probe_range_limit_is_on_the_zero_to_peak_amplitude(tmp_path):
    """40 mm peak to peak is 20 mm of orbit radius: within a probe's 25 mm; 40 mm zero to peak is not."""
    rows = "\n".join(f"{r},{a},{p}" for r, a, p in zip(np.linspace(500, 3000, 12), np.full(12, 40.0),
                                                       np.linspace(0, 180, 12), strict=True))
    path = tmp_path / "big.csv"
    path.write_text("rpm,amp,phase_deg\n" + rows + "\n")
    table = load_vector_table(path, amp_unit="mm pp")
    assert np.allclose(np.abs(table.vectors[1]), 20.0)
    with pytest.raises(VectorTableError, match=r"big.csv, line 2, column 'amp': amplitude 40.0 mm is beyond"):
        load_vector_table(path, amp_unit="mm")


def test_a_peak_to_peak_table_read_as_such_gives_the_zero_to_peak_diagnosis(tables):
    """The same bowed run from its zero-to-peak and its peak-to-peak table: the same bow, floor
    and critical; the peak-to-peak table read as zero to peak doubles every size and leaves the
    critical, the damping and the verdict alone (why the measure must be said)."""
    angles = {"x": 45.0, "y": -45.0}
    out = {}
    for key, name, unit in (("pk", "pk", "um"), ("pp", "pp", "um pp"), ("pp_as_pk", "pp", "um")):
        d = diagnose_vectors(load_vector_table(tables / f"{name}.csv", amp_unit=unit, angles=angles),
                             candidates=["shaft_bow", "runout"]).to_dict()
        out[key] = d
    pk, pp, wrong = out["pk"], out["pp"], out["pp_as_pk"]
    for d in (pk, pp, wrong):
        assert d["missing"] == ["shaft_bow"] and d["verdict"] == "explained_after_adding"
    assert pk["physical"]["shaft_bow"]["bow"] == pytest.approx(4.0, rel=0.02)  # um, the truth
    assert pp["physical"]["shaft_bow"]["bow"] == pytest.approx(pk["physical"]["shaft_bow"]["bow"], rel=1e-6)
    assert pp["noise_floor"] == pytest.approx(pk["noise_floor"], rel=1e-6)
    assert wrong["physical"]["shaft_bow"]["bow"] == pytest.approx(2 * pk["physical"]["shaft_bow"]["bow"], rel=1e-6)
    assert wrong["noise_floor"] == pytest.approx(2 * pk["noise_floor"], rel=1e-6)
    for d in (pp, wrong):
        assert d["criticals"][0]["rpm"] == pytest.approx(pk["criticals"][0]["rpm"], rel=1e-6)
        assert d["criticals"][0]["damping_ratio"] == pytest.approx(pk["criticals"][0]["damping_ratio"], rel=1e-6)
    assert any("peak to peak" in n for n in pp["notes"])


def test_the_command_lines_take_the_measure_and_refuse_an_unknown_unit(tables, capsys):
    rig = str(tables / "rig.yaml")
    assert main(["diagnose", str(tables / "pp.csv"), "--vectors", "--rig", rig, "--amp-unit", "um pp",
                 "--model", "viscous_damping,unbalance,shaft_bow", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["physical"]["shaft_bow"]["bow"] == pytest.approx(4.0, rel=0.02)
    for cmd in (["diagnose", str(tables / "pp.csv"), "--vectors"], ["balance", str(tables / "pp.csv"), "--runs", rig]):
        with pytest.raises(SystemExit) as exc:
            main([*cmd, "--amp-unit", "furlong pp"])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert "'furlong pp': expected one of um, µm, mil, mm, m" in err, err


def test_a_peak_to_peak_balancing_table_gives_the_same_correction_in_zero_to_peak_units(tmp_path):
    """Influence coefficients are ratios of vectors: the correction weight is the same whatever
    the measure; the vibration reported (each run's 1X, the predicted residual) is zero to peak."""
    camp = Campaign((Plane("A", 100.0),), "ref", {"T1": {"A": (5.0, 0.0)}, "T2": {"A": (8.0, 120.0)}},
                    source="RUNS.yaml")
    W = camp.trial_matrix()
    header, rows = campaign_table(DiskRotor(), (1200.0, 1500.0, 2000.0), np.array([weight(6.0, 100.0, 30.0)]),
                                  {r: W[k] for k, r in enumerate(camp.runs)}, seed=7, probe_names=("x", "y"))
    amp = [j for j, h in enumerate(header) if h.endswith("_amp")]
    for name, factor in (("pk", 1.0), ("pp", 2.0)):
        with open(tmp_path / f"{name}.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows([[v * factor if j in amp else v for j, v in enumerate(r)] for r in rows])
    runs = tmp_path / "runs.yaml"
    runs.write_text("planes: {A: {radius_mm: 100, holes: 12}}\nreference: ref\nruns:\n"
                    "  T1: {A: {mass_g: 5, angle_deg: 0}}\n  T2: {A: {mass_g: 8, angle_deg: 120}}\n")
    pk = balance(tmp_path / "pk.csv", runs).to_dict()
    pp = balance(tmp_path / "pp.csv", runs, amp_unit="um pp").to_dict()
    for key in ("mass_g", "angle_deg"):
        assert pp["correction"]["A"][key] == pytest.approx(pk["correction"]["A"][key], rel=1e-9, abs=1e-9)
    assert pp["runs"]["ref"]["unbalance"]["A"]["g_mm"] == pytest.approx(pk["runs"]["ref"]["unbalance"]["A"]["g_mm"],
                                                                       rel=1e-9)
    first = pk["influence"][0]["amp_per_g_mm"]
    assert pp["influence"][0]["amp_per_g_mm"] == pytest.approx(first, rel=1e-9)
