"""``rotor-id --version`` starts fast (issue 25, item 8): the command line and the package
``__init__``s import only what the command uses."""

from __future__ import annotations

import json
import subprocess
import sys

# what a --version / --help must not load: the numerics (scipy, numba), the diagnosis, the
# monitor's core, Stable-Baselines3 / torch, Ray, matplotlib
HEAVY = ("scipy", "numba", "matplotlib", "torch", "stable_baselines3", "ray", "pyarrow",
         "identifier", "rotor_env.diagnosis", "rotor_env.monitor.core", "rotor_env.simulator")

PROBE = """
import json, sys
from rotor_env.cli import build_parser
parser = build_parser()
try:
    parser.parse_args(["--version"])
except SystemExit:
    pass
print(json.dumps(sorted(m for m in sys.modules)))
"""


def test_version_and_parser_import_no_numerics():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True, timeout=120)
    loaded = set(json.loads(out.stdout.splitlines()[-1]))
    heavy = sorted(m for m in loaded if any(m == h or m.startswith(h + ".") for h in HEAVY))
    assert not heavy, f"rotor-id --version imports {heavy[:10]}"


def test_lazy_package_attributes_still_there():
    import rotor_env
    import rotor_env.monitor

    assert callable(rotor_env.diagnose) and callable(rotor_env.simulate)
    assert rotor_env.RotorParams is __import__("rotor_env.params", fromlist=["RotorParams"]).RotorParams
    assert rotor_env.monitor.Monitor.__module__ == "rotor_env.monitor.core"
    assert set(rotor_env.__all__) <= set(dir(rotor_env))
    assert "rub" in rotor_env.PACKAGE_EFFECTS
