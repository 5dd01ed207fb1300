"""Issue 22, "Done when": a seeded mutation loop over rig YAML, 1X vector tables and monitor
streams (180 mutations) in a child process with its address space capped at 3 GiB and a
wall-clock limit: no traceback, no hang, no allocation past the cap, no silent non-finite
output, every refusal short and naming its file (tests/attack_fuzz.py; a bigger run with
full diagnoses: scripts/fuzz_inputs.py)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import attack_fuzz


def test_seeded_mutations_give_no_traceback_hang_or_silent_nan():
    out = attack_fuzz.run_in_subprocess(60, seed=22, memory_gb=3.0, timeout_s=150, per_case_s=20)
    assert out["mutations"] == 180, out["failures"]
    assert out["failures"] == []
    # the loop reaches past the readers' first checks: some inputs are read, most refused
    assert out["counts"]["ok"] >= 10 and out["counts"]["refused"] >= 60


def test_the_fuzzer_catches_a_traceback_and_a_silent_nan(tmp_path, monkeypatch):
    """The oracle itself: a reader that raises TypeError, hands out NaN, or refuses in numpy's
    words, is a failure."""
    import numpy as np

    def raises(path, full):
        raise TypeError("unhashable type: 'list'")

    def nan(path, full):
        attack_fuzz._finite(np.array([1.0, np.nan]), "a column")

    def numpy_words(path, full):
        raise np.linalg.LinAlgError(f"{path}: SVD did not converge")  # a ValueError, named, but numpy's words

    monkeypatch.setitem(attack_fuzz.TARGETS, "rig", (".yaml", raises))
    monkeypatch.setitem(attack_fuzz.TARGETS, "table", (".csv", nan))
    monkeypatch.setitem(attack_fuzz.TARGETS, "stream", (".csv", numpy_words))
    out = attack_fuzz.run(2, seed=1, kinds=("rig", "table", "stream"))
    whys = [f["why"] for f in out["failures"]]
    assert len(whys) == 6
    assert any("TypeError" in w for w in whys) and any("silent non-finite" in w for w in whys)
    assert sum("unclear refusal" in w and "SVD" in w for w in whys) == 2


def test_the_fuzz_script_answers_help_bad_arguments_and_a_small_run():
    """scripts/fuzz_inputs.py: --help and a bad N are answered without a traceback (N was
    parsed with int() before: '--help' raised ValueError); a small run prints its counts."""
    import json
    import subprocess

    script = Path(__file__).resolve().parents[1] / "scripts" / "fuzz_inputs.py"

    def run(*args):
        return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, timeout=300)

    out = run("--help")
    assert out.returncode == 0 and "mutations per kind" in out.stdout
    for bad in (["abc"], ["0"], ["3", "--full-share", "2"]):
        out = run(*bad)
        assert out.returncode == 2 and "Traceback" not in out.stderr and "error:" in out.stderr
    out = run("3", "1", "--full-share", "0.5", "--per-case", "60", "--timeout", "250")
    result = json.loads(out.stdout)
    assert out.returncode == 0 and result["mutations"] == 9 and result["failures"] == []
