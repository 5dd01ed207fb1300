"""Start-up cost: the first and the second process of a command (numba's on-disk cache).

Each command runs in a fresh process twice with the same, initially empty, cache folders
(``NUMBA_CACHE_DIR`` for numba, ``ROTOR_ID_CACHE_DIR`` for the generated simulator
kernels): the first start compiles and writes the cache, the second reads it.  A third
run of the second kind with ``ROTOR_ID_NO_KERNEL_CACHE=1`` shows what the generated-kernel
cache saves (the compiled-in-memory path every process took before).

    python benchmarks/startup.py [--repeat 1]

Prints a Markdown table: wall seconds per start and the ratios.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent

EPISODE = (
    "import gymnasium as gym, rotor_env\n"
    "from rotor_env import IdentificationWrapper\n"
    "env = IdentificationWrapper(gym.make('rotor_env/RotorRunUp-v0'))\n"
    "obs, _ = env.reset(seed=0)\n"
    "done = False\n"
    "while not done:\n"
    "    obs, r, term, trunc, _ = env.step(env.action_space.sample() * 0 + 1)\n"
    "    done = term or trunc\n"
)


def timed(cmd: list[str], env: dict) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=HERE)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1, help="fresh caches per command (best of)")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="rotor-id-startup-"))
    data = work / "run_up.csv"
    rid = str(BIN / "rotor-id")
    subprocess.run([rid, "simulate", str(data), "--noise", "5e-4", "--seed", "1", "--crack", "250:0.05",
                    "--set", "h=0"], check=True, stdout=subprocess.DEVNULL)
    commands = {
        "rotor-id --version": [rid, "--version"],
        "rotor-id simulate (t 0-400)": [rid, "simulate", str(work / "out.csv"), "--force"],
        "rotor-id diagnose (40 000 samples)": [rid, "diagnose", str(data), "--json"],
        "wrapped RunUp episode": [sys.executable, "-c", EPISODE],
    }
    print("| command | first start (s) | second start (s) | first / second | second, kernel cache off (s) | off / on |")
    print("|---|---|---|---|---|---|")
    for name, cmd in commands.items():
        firsts, seconds, offs = [], [], []
        for r in range(args.repeat):
            env = dict(os.environ, NUMBA_CACHE_DIR=str(work / f"numba{r}"),
                       ROTOR_ID_CACHE_DIR=str(work / f"kernels{r}"))
            env.pop("ROTOR_ID_NO_KERNEL_CACHE", None)
            firsts.append(timed(cmd, env))
            seconds.append(timed(cmd, env))
            offs.append(timed(cmd, dict(env, ROTOR_ID_NO_KERNEL_CACHE="1")))
        f, s, o = min(firsts), min(seconds), min(offs)
        print(f"| {name} | {f:.2f} | {s:.2f} | ×{f / s:.2f} | {o:.2f} | ×{o / s:.2f} |", flush=True)


if __name__ == "__main__":
    main()
