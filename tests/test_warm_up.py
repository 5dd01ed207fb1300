"""``rotor-id warm-up``: the measured-data kernels compiled and cached once per machine.

Timing is not tested (a benchmark's job: ``benchmarks/rig_speed.py`` times the first and the
warm runs); what is: the command runs the rig and the 1X-table diagnoses end to end on its
own short record, says what it did, writes the generated kernels into the kernel cache
folder and nothing into the working folder.
"""

from __future__ import annotations

import os

from rotor_env.cli import main
from rotor_env.simulator import kernel_cache_dir


def test_warm_up_compiles_the_kernels_and_writes_nothing_else(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["warm-up"]) == 0
    out = capsys.readouterr().out
    assert "rotor-id warm-up: the diagnosis's kernels are compiled and cached" in out
    for stage in ("simulation", "rig diagnosis", "1X table diagnosis"):
        assert stage in out
    kernels = os.listdir(kernel_cache_dir() / "kernels")
    assert any(k.startswith("rotor_id_oe_") for k in kernels)  # the output-error shooting kernel
    assert any(k.startswith("rotor_id_kernel_") for k in kernels)  # the simulator's
    assert list(tmp_path.iterdir()) == []
