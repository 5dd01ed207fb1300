"""A seeded mutation fuzzer over rig YAML, 1X vector tables and monitor streams (issue 22).

Each mutation is fed to the layer that reads it (``load_rig``; ``load_vector_table`` and
the vector noise floor, with a full ``diagnose_vectors`` on a share of the tables in the
bigger run; ``StreamReader`` + ``Monitor``) and classified:

* ``ok``: read; every number handed out is finite (a NaN or inf out is a failure);
* ``refused``: a ``ValueError`` (the package's errors derive from it) whose message names
  the input and is short (no unbounded value echoed), in its own words (not numpy's:
  :data:`RAW_WORDS`);
* a failure: any other exception (a traceback for the user), a refusal without the file's
  name or over :data:`MAX_MESSAGE` characters, a mutation over ``per_case_s`` (a hang),
  a ``MemoryError`` (an allocation the input drove past the address-space cap).

:func:`run_in_subprocess` runs :func:`run` in a child with ``RLIMIT_AS`` capped and a
wall-clock timeout; ``tests/test_attack_fuzz.py`` runs a few hundred mutations in CI time,
``scripts/fuzz_inputs.py`` thousands.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path

import numpy as np

MAX_MESSAGE = 1000
#: numpy's and Python's own words in a refusal: they tell a user nothing about the input (item 8)
RAW_WORDS = ("SVD did not converge", "cannot reshape array", "cannot convert float NaN to integer", "np.float64(",
             "could not convert string to float", "index out of bounds", "Traceback")

HOSTILE = ["nan", "inf", "-inf", "1e300", "-1e300", "1e-300", "0", "-1", "4" * 400, "true", "no", "[1, 2]",
           "{a: 1}", "", "~", "&a 5", "*a", "!!binary aGk=", "x" * 5000, "1e200", "0x1F", "1_000", "'45'",
           "[" * 200 + "]" * 200, "\x00", "é", "2e5", "-0"]

RIG = """keyphasor: kp
time: t
units: {time: s, displacement: um, speed: rpm}
probes:
  - {name: x, angle_deg: 45, plane: A}
  - {name: y, angle_deg: -45, plane: A}
planes: {A: {axial_position_m: 0.0}}
model: auto
disk: {ip: 0.0, mass_kg: 2.0}
slow_roll_rpm: 400
"""


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang()


# ------------------------------------------------------------------ inputs
def _vector_text(rows: int = 40) -> str:
    rpm = np.linspace(600.0, 2400.0, rows)
    r = rpm / 1650.0
    X = 20.0 * r**2 / (1 - r**2 + 2j * 0.02 * r)
    t = np.cumsum(np.r_[0.0, 600.0 / rpm[1:]])
    lag = np.degrees(-np.angle(X)) % 360
    cols = [t, rpm, np.abs(X), lag, np.abs(X), (lag + 90) % 360]
    lines = ["t,rpm,x_amp,x_phase_deg,y_amp,y_phase_deg"]
    lines += [",".join(f"{c[i]:.8g}" for c in cols) for i in range(rows)]
    return "\n".join(lines) + "\n"


def _stream_text(rows: int = 1500) -> str:
    from rotor_env.monitor.scenarios import with_crack

    meas = with_crack(0.0, 0.04).slice_time(0, rows * 0.01)
    data = meas.data[:rows]
    from rotor_env.measurements import COLUMNS

    return ",".join(COLUMNS) + "\n" + "\n".join(",".join(f"{v:.10g}" for v in row) for row in data) + "\n"


def _mutate_text(text: str, rng: random.Random) -> str:
    """One hostile edit of a text: a token, a line, bytes, endings, scale, truncation."""
    lines = text.splitlines()
    kind = rng.choice(["token", "token", "token", "line_del", "line_dup", "swap", "truncate", "cr", "long",
                       "scale", "header", "bytes", "fields"])
    if kind in ("token", "scale"):
        i = rng.randrange(len(lines))
        parts = lines[i].replace(":", ",").split(",") if "," in lines[i] or ":" in lines[i] else [lines[i]]
        j = rng.randrange(len(parts))
        old = parts[j].strip().strip("{}[] ")
        if kind == "scale":
            try:
                new = repr(float(old) * rng.choice([1e3, 1e-3, 1e6, 1e-6, 57.2957795, 1e300, -1]))
            except ValueError:
                new = rng.choice(HOSTILE)
        else:
            new = rng.choice(HOSTILE)
        if old:
            lines[i] = lines[i].replace(old, new, 1)
        else:
            lines[i] += new
    elif kind == "line_del" and len(lines) > 2:
        del lines[rng.randrange(1, len(lines))]
    elif kind == "line_dup":
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
    elif kind == "swap" and len(lines) > 3:
        i, j = rng.randrange(1, len(lines)), rng.randrange(1, len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    elif kind == "truncate":
        return text[: rng.randrange(len(text))]
    elif kind == "cr":
        return text.replace("\n", "\r")
    elif kind == "long":
        lines.insert(rng.randrange(len(lines)), "9" * rng.choice([70_000, 300_000]))
    elif kind == "header":
        cells = lines[0].split(",")
        cells[rng.randrange(len(cells))] = rng.choice(["t", "rpm", "x_amp", "kp", "", "x_amp", "phi", "T", "Rpm"])
        lines[0] = ",".join(cells)
    elif kind == "bytes":
        b = bytearray(text.encode())
        for _ in range(rng.randint(1, 5)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return b.decode("latin-1")
    elif kind == "fields":
        i = rng.randrange(1, len(lines))
        lines[i] = lines[i] + ",1" if rng.random() < 0.5 else lines[i].rsplit(",", 1)[0]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ the targets
def _finite(values, what: str) -> None:
    arr = np.asarray(values, dtype=complex if np.iscomplexobj(values) else float)
    if arr.size and not np.all(np.isfinite(arr)):
        raise AssertionError(f"silent non-finite output: {what}")


def _rig(path: Path, full: bool) -> None:
    from rotor_env.measurements.rig import load_rig

    rig = load_rig(path)
    _finite([p.angle for p in rig.probes] + [rig.ip, *rig.planes.values()], "rig angles/positions")


def _table(path: Path, full: bool) -> None:
    from rotor_env.diagnosis.from_vectors import diagnose_vectors, vector_noise_floor
    from rotor_env.measurements.vectors import load_vector_table

    table = load_vector_table(path)
    _finite(table.speed, "table speeds")
    _finite(table.vectors[1], "table 1X vectors")
    floor = vector_noise_floor(table)
    _finite([floor], "noise floor")
    if full:
        result = diagnose_vectors(table)
        _finite([result.after.rms, result.before.rms], "diagnosis RMS")
        _finite([c["rpm"] for c in result.after.criticals], "critical speeds")


def _stream(path: Path, full: bool) -> None:
    from rotor_env.monitor import Monitor, StreamReader

    mon = Monitor()
    try:
        for chunk in StreamReader(path):
            for event in mon.update(chunk):
                _finite([v for v in event.values() if isinstance(v, float)], f"monitor {event['event']} event")
    finally:
        summary = mon.summary()
        _finite([summary["t"], summary["samples"]], "monitor summary")


TARGETS = {"rig": (".yaml", _rig), "table": (".csv", _table), "stream": (".csv", _stream)}


def run(n: int, seed: int = 0, *, per_case_s: float = 20.0, full_share: float = 0.0, kinds=tuple(TARGETS)) -> dict:
    """``n`` mutations per kind (``seed``: reproducible); returns counts and the failures."""
    from rotor_env.measurements.rig import RigError  # noqa: F401 - imported before the cap bites

    rng = random.Random(seed)
    seeds = {"rig": RIG, "table": _vector_text(), "stream": _stream_text()}
    signal.signal(signal.SIGALRM, _alarm)
    counts = {"ok": 0, "refused": 0}
    failures = []
    with tempfile.TemporaryDirectory(prefix="rotor-id-fuzz-") as tmp:
        for kind in kinds:
            suffix, target = TARGETS[kind]
            # the unmutated seed once, untimed: it must be read, and it compiles the numba kernels
            # (a fresh clone has no cache; compiling is not a hang the input caused)
            warm = Path(tmp) / f"{kind}-seed{suffix}"
            warm.write_text(seeds[kind])
            try:
                target(warm, False)
            except Exception:  # judged below, with every mutation, not here
                pass
            warm.unlink()
            for k in range(n):
                text = seeds[kind]
                for _ in range(rng.choice([1, 1, 2, 3])):
                    text = _mutate_text(text, rng)
                path = Path(tmp) / f"{kind}{k}{suffix}"
                path.write_bytes(text.encode("utf-8", errors="surrogateescape"))
                full = rng.random() < full_share
                signal.setitimer(signal.ITIMER_REAL, per_case_s)
                try:
                    target(path, full)
                    counts["ok"] += 1
                except _Hang:
                    failures.append({"kind": kind, "case": k, "why": f"over {per_case_s} s (a hang)", "input": text[:300]})
                except MemoryError:
                    failures.append({"kind": kind, "case": k, "why": "MemoryError (unbounded allocation)",
                                     "input": text[:300]})
                except ValueError as exc:
                    msg = str(exc)
                    if len(msg) > MAX_MESSAGE or str(path) not in msg or any(w in msg for w in RAW_WORDS):
                        failures.append({"kind": kind, "case": k, "why": f"unclear refusal: {msg[:300]!r}",
                                         "input": text[:300]})
                    else:
                        counts["refused"] += 1
                except Exception as exc:  # a traceback for the user, or a silent non-finite output
                    failures.append({"kind": kind, "case": k, "why": f"{type(exc).__name__}: {str(exc)[:200]}",
                                     "trace": traceback.format_exc()[-1500:], "input": text[:300]})
                finally:
                    signal.setitimer(signal.ITIMER_REAL, 0)
                path.unlink()
    return {"counts": counts, "failures": failures, "mutations": n * len(kinds), "seed": seed}


def run_in_subprocess(n: int, seed: int = 0, *, memory_gb: float = 3.0, timeout_s: float = 300.0,
                      per_case_s: float = 20.0, full_share: float = 0.0) -> dict:
    """:func:`run` in a child process with its address space capped at ``memory_gb``."""
    code = (f"import json, resource, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
            f"cap = int({memory_gb} * 2**30); resource.setrlimit(resource.RLIMIT_AS, (cap, cap)); "
            f"import attack_fuzz; print(json.dumps(attack_fuzz.run({n}, {seed}, per_case_s={per_case_s}, "
            f"full_share={full_share})))")
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout_s,
                              env=env)
    except subprocess.TimeoutExpired:  # a hang inside C code, where the per-case alarm cannot land
        return {"counts": {}, "failures": [{"why": f"the fuzz process ran over {timeout_s:g} s (a hang)"}],
                "mutations": 0, "seed": seed}
    if proc.returncode != 0:
        return {"counts": {}, "failures": [{"why": f"the fuzz process died (rc {proc.returncode})",
                                            "trace": proc.stderr[-3000:]}], "mutations": 0, "seed": seed}
    return json.loads(proc.stdout.strip().splitlines()[-1])


if __name__ == "__main__":  # pragma: no cover
    out = run_in_subprocess(int(sys.argv[1]) if len(sys.argv) > 1 else 50)
    print(json.dumps(out, indent=1)[:20000])
