"""Compile the diagnosis's kernels once per machine: ``rotor-id warm-up``.

Why
---
The rig diagnosis runs on numba kernels (the output-error shooting with every library effect,
the second mode's, the projections, the synchronous model, the order tracking).  numba
compiles them the first time they run and keeps them on disk (the generated kernels in the
kernel cache folder, :func:`rotor_env.simulator.kernel_cache_dir`, each with numba's cache
beside it; the package's own in its ``__pycache__``), so every later process loads them in a
fraction of a second.  On a 2-core machine that first compilation takes 40-50 s: a 15 s rig
record diagnosed in 12 s warm takes about 55 s the first time.  ``scripts/run-demo.sh`` runs
this command after setting up, so that the first record a user diagnoses runs at the speed
the README states.

What it does: simulates a short rig run-up through the critical (4 s at 5 kHz, an open crack,
0.5 um probe noise; in a temporary folder, removed afterwards) and diagnoses it as
``rotor-id diagnose RUN --rig rig.yaml`` and its 1X table as ``rotor-id diagnose TABLE --vectors``
do, with the whole library.  Once warm it takes a few seconds; it writes nothing else.  The
kernels are compiled for the types they meet, which are the same for every record: a
record of any length or rate, in any unit, then loads them.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

__all__ = ["warm_up"]

#: the short record: a run-up through the 1650 rpm critical with an open crack
_RIG = {"keyphasor": "kp", "probes": {"x": 45, "y": -45}, "units": {"displacement": "um"}}
_VALUES = {"k": 1.0, "c": 0.04, "tau": 0.005, "beta": 0.7, "D": 0.03, "D_axis": 0.5}


def warm_up(*, progress: bool = False) -> dict[str, float]:
    """Compile (or load) every kernel of the rig and 1X-table diagnoses; seconds per stage."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from .batch import diagnose_file
    from .measurements.rig import load_rig
    from .params import RotorParams
    from .progress import step
    from .rig_simulation import simulate_rig

    seconds: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="rotor_id_warm_up_") as tmp:
        folder = Path(tmp)
        rig_path = folder / "rig.json"
        rig_path.write_text(json.dumps(_RIG))
        rig = load_rig(rig_path)
        step("warm-up: simulating a short rig run-up (4 s at 5 kHz, an open crack)")
        t0 = time.perf_counter()
        params = RotorParams(ip=0.0, values=dict(_VALUES),
                             effects=("stiffness", "viscous_damping", "unbalance", "asymmetry"))
        run = simulate_rig(rig, params, natural_rpm=1650.0, rpm_from=600.0, rpm_to=2700.0, rpm_per_s=525.0,
                           sample_rate=5000.0, noise=0.5, seed=1)
        pq.write_table(pa.table(run.file_columns()), folder / "run.parquet")
        run.vectors(rig).to_csv(folder / "vectors.csv", phase="lag")
        seconds["simulation"] = time.perf_counter() - t0
        step("warm-up: the rig diagnosis's kernels (compiled once per machine and code version)")
        t0 = time.perf_counter()
        diagnose_file(folder / "run.parquet", rig=rig, progress=progress)
        seconds["rig diagnosis"] = time.perf_counter() - t0
        step("warm-up: the 1X table's diagnosis")
        t0 = time.perf_counter()
        diagnose_file(folder / "vectors.csv", rig=rig, vectors=True, progress=progress)
        seconds["1X table diagnosis"] = time.perf_counter() - t0
    return seconds
