"""Acceptance: the paper's numerical study (Zhou & Shi 2004, Table 2) re-run online.

Significance is statistical, so every case is run with the ten noise seeds 0..9
(fixed in advance, never chosen to pass) and the decisions are judged over them.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rotor_env import cli
from rotor_env.paper import CASES, PAPER_TABLE2, TERMS, run_case

SEEDS = tuple(range(10))
READ_AT = 300.0
TESTED = TERMS[1:]  # tau is the first column: it has no nested F
#: parameters the data identify poorly (PHYSICS.md section 5 and Table 2): c after
#: resonance in case 1 (nearly collinear with h in the circular whirl), and the
#: quadratic stiffness in case 2 (no dry friction: a small whirl, weak quadratic terms)
POORLY_IDENTIFIABLE = {("1", "c"), ("2", "k21"), ("2", "k12"), ("2", "k03")}


@pytest.fixture(scope="module")
def study() -> dict:
    """case -> (truth, [reading at t = 300 for each seed])."""
    out = {}
    for name in CASES:
        readings, truth = [], None
        for seed in SEEDS:
            case = run_case(name, seed)
            truth = case.truth()
            readings.append(case.reading(READ_AT))
        out[name] = (truth, readings)
    return out


def _agrees(term_reading: dict, paper: bool | None) -> bool:
    return paper is None or term_reading["significant"] is paper


def test_every_decision_agrees_with_table2_in_most_seeds(study):
    lines, total, agree = [], 0, 0
    for name, (_, readings) in study.items():
        for term in TESTED:
            paper = PAPER_TABLE2[name][term][2]
            hits = sum(_agrees(r[term], paper) for r in readings)
            total += len(readings)
            agree += hits
            if not hits > len(readings) / 2:
                lines.append(f"case {name} {term}: {hits}/{len(readings)} agree with {paper}")
    assert total == 4 * 6 * len(SEEDS)
    assert not lines, "; ".join(lines)
    assert agree >= 0.95 * total, f"{agree}/{total} decisions agree with Table 2"


def test_mean_estimates_match_the_truth(study):
    """Mean over the seeds within 10 % of every non-zero true parameter; the poorly
    identifiable ones within 3 standard errors of the mean.

    Which standard error: the quantity tested is the *mean* of 10 estimates from
    independent noise seeds, whose standard deviation is the single-run standard error
    divided by sqrt(10) (the simulation is deterministic, only the noise on y changes).
    So the yardstick is the standard error of the mean, ``mean(se) / sqrt(10)``.  The
    mean single-run standard error would be sqrt(10) ~ 3.2x looser: it asks whether one
    run is consistent with the truth, not whether the estimator is unbiased; it would
    let a bias of up to ~10 single-run SEMs pass.  (Deterministic biases — the prior's
    ridge shrinkage, the friction regressor's regularisation — do not average out, so
    this is the stricter, and the honest, check.)
    """
    problems = []
    for name, (truth, readings) in study.items():
        for term in TERMS:
            true = truth[term]
            est = np.array([r[term]["estimate"] for r in readings])
            se = np.array([r[term]["standard_error"] for r in readings])
            assert np.isfinite(est).all() and (se > 0).all()
            mean = est.mean()
            sem = se.mean() / math.sqrt(len(readings))
            if (name, term) in POORLY_IDENTIFIABLE:
                if abs(mean - true) > 3.0 * sem:
                    problems.append(f"case {name} {term}: mean {mean:.5g}, truth {true:.5g}, "
                                    f"3 SEM {3 * sem:.2g}")
            elif true != 0.0 and abs(mean - true) > 0.10 * abs(true):
                problems.append(f"case {name} {term}: mean {mean:.5g} vs truth {true:.5g} (> 10 %)")
    assert not problems, "; ".join(problems)


def test_absent_effects_are_estimated_near_zero(study):
    """The zeroed parameter of cases 2-4 (h, D, k12): mean within 3 SEM of 0."""
    for name, term in (("2", "h"), ("3", "D"), ("4", "k12")):
        truth, readings = study[name]
        assert truth[term] == 0.0
        est = np.array([r[term]["estimate"] for r in readings])
        sem = np.mean([r[term]["standard_error"] for r in readings]) / math.sqrt(len(readings))
        assert abs(est.mean()) < 3.0 * sem, (name, term, est.mean(), sem)


def test_standard_errors_are_calibrated(study):
    """The reported standard error matches the scatter over the seeds.

    Pooled over all 28 (case, term) pairs (9 degrees of freedom each, 252 in all), the
    RMS ratio of the empirical standard deviation to the mean reported standard error
    lies in [0.7, 1.3]; one pair alone would scatter too much to test (chi with 9 dof).
    """
    ratios = []
    for _, (_, readings) in study.items():
        for term in TERMS:
            est = np.array([r[term]["estimate"] for r in readings])
            se = np.array([r[term]["standard_error"] for r in readings])
            ratios.append(est.std(ddof=1) / se.mean())
    pooled = math.sqrt(float(np.mean(np.square(ratios))))
    assert 0.7 < pooled < 1.3, pooled


def test_reading_layout():
    case = run_case("2", seed=0)
    r = case.reading(READ_AT)
    assert list(r) == list(TERMS)
    assert set(r["tau"]) == {"estimate", "standard_error"}
    for term in TESTED:
        assert set(r[term]) == {"estimate", "standard_error", "F", "significant"}
        assert isinstance(r[term]["significant"], bool)
    assert case.coefficients.shape == (len(case.t), len(TERMS))
    assert case.F.shape == case.log10_p.shape == (len(case.t), len(TERMS))
    assert case.t[-1] == pytest.approx(400.0)
    assert case.truth()["h"] == 0.0 and case.label == "h = 0"


# ------------------------------------------------------------------ the CLI
def test_cli_paper_json(capsys):
    assert cli.main(["paper", "--json", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    data = json.loads(out)
    assert set(data) == {"1", "2", "3", "4"}
    for name, effects in data.items():
        assert list(effects) == ["tau", "D", "c", "k21", "k12", "k03", "h"], name
        assert set(effects["tau"]) == {"estimate"}
        assert isinstance(effects["tau"]["estimate"], float)
        for term in TESTED:
            row = effects[term]
            assert set(row) == {"estimate", "F", "significant"}, (name, term)
            assert isinstance(row["estimate"], float) and isinstance(row["F"], float)
            assert isinstance(row["significant"], bool)
    # the same numbers as the library call with that seed
    ref = run_case("4", seed=3).reading(READ_AT)
    assert data["4"]["k12"]["F"] == ref["k12"]["F"]
    assert data["4"]["D"]["estimate"] == ref["D"]["estimate"]


def test_cli_paper_out_writes_figures_and_tables(tmp_path, capsys):
    out = tmp_path / "paper"
    assert cli.main(["paper", "--out", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert "case 1 (Table 1) at t = 300" in stdout and str(out) in stdout
    for name in ("fig3_response.png", "fig4_parameters.png", "fig5_significance.png",
                 "table2.md", "table2.csv"):
        path = out / name
        assert path.is_file() and path.stat().st_size > 0, name
        if name.endswith(".png"):
            assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    md = (out / "table2.md").read_text()
    assert "## Case 4: k12 = 0" in md and "| h |" in md
    rows = (out / "table2.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 4 * len(TERMS)
    # a non-empty folder is not written into without --force
    assert cli.main(["paper", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
