"""Issue 11: random mutations of a valid CSV (seeded) through ``load_measurements`` and a quick
``fit``: no traceback other than the project's own errors, no hang, no silent non-finite output."""

from __future__ import annotations

import math
import signal
import time

import numpy as np
import pytest

from rotor_env.diagnosis import fit
from rotor_env.measurements.files import MeasurementError, load_measurements
from rotor_env.params import RotorParams
from rotor_env.simulator import SimulationError, simulate

CASES = 300
SEED = 20240611
#: seconds one case may take (a load and a fit of 2 000 samples take ~0.1 s)
BUDGET = 10.0
MODEL = ["unbalance", "viscous_damping"]

TOKENS = ["nan", "NaN", "inf", "-inf", "1e300", "-1e300", "1e31", "1e-320", "", " ", "abc", "0x10", "1_0",
          "1e", "--1", "1,2", '"3"', "\x00", "é", "9" * 400, "-0", "1e308", "4.9e-324", "true", "NA"]


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang


@pytest.fixture(scope="module")
def valid_csv(tmp_path_factory) -> bytes:
    meas = simulate(RotorParams(), t_end=200.0, dt=0.1, noise=5e-4, seed=2)
    path = meas.to_file(tmp_path_factory.mktemp("fuzz") / "valid.csv")
    return path.read_bytes()


def _mutate(rng: np.random.Generator, text: bytes) -> bytes:
    lines = text.decode().split("\n")
    header, rows = lines[0], [ln for ln in lines[1:] if ln]
    kind = int(rng.integers(18))
    r = int(rng.integers(len(rows)))
    cells = rows[r].split(",")
    c = int(rng.integers(len(cells)))
    if kind == 0:  # a cell replaced by an odd token
        cells[c] = TOKENS[int(rng.integers(len(TOKENS)))]
        rows[r] = ",".join(cells)
    elif kind == 1:  # a cell scaled by a wild factor
        cells[c] = repr(float(cells[c]) * 10.0 ** float(rng.uniform(-300, 300)))
        rows[r] = ",".join(cells)
    elif kind == 2:  # a cell dropped or one added
        if rng.random() < 0.5:
            del cells[c]
        else:
            cells.insert(c, "0")
        rows[r] = ",".join(cells)
    elif kind == 3:  # rows deleted, duplicated or swapped
        k = int(rng.integers(1, 50))
        choice = int(rng.integers(3))
        if choice == 0:
            del rows[r : r + k]
        elif choice == 1:
            rows[r:r] = rows[r : r + k]
        else:
            s = int(rng.integers(len(rows)))
            rows[r], rows[s] = rows[s], rows[r]
    elif kind == 4:  # blank lines
        for _ in range(int(rng.integers(1, 5))):
            rows.insert(int(rng.integers(len(rows))), "" if rng.random() < 0.5 else " , ")
    elif kind == 5:  # a column scaled (units)
        factor = 10.0 ** float(rng.choice([-12, -6, -3, 3, 6, 12, 100]))
        rows = [",".join(repr(float(v) * factor) if j == c else v for j, v in enumerate(row.split(",")))
                for row in rows]
    elif kind == 6:  # a column made constant
        rows = [",".join("0.5" if j == c else v for j, v in enumerate(row.split(","))) for row in rows]
    elif kind == 7:  # the header changed: a name misspelt, duplicated, dropped
        names = header.split(",")
        choice = int(rng.integers(3))
        if choice == 0:
            names[c] = names[c][:-1] + "X"
        elif choice == 1:
            names[c] = names[(c + 1) % len(names)]
        else:
            names[c] = ""
        header = ",".join(names)
    elif kind == 8:  # truncated at a random byte
        out = (header + "\n" + "\n".join(rows) + "\n").encode()
        return out[: int(rng.integers(len(out)))]
    elif kind == 9:  # random bytes spliced in
        out = bytearray((header + "\n" + "\n".join(rows) + "\n").encode())
        at = int(rng.integers(len(out)))
        out[at:at] = rng.integers(0, 256, int(rng.integers(1, 20)), dtype=np.uint8).tobytes()
        return bytes(out)
    elif kind == 10:  # a text column added
        header += ",note"
        rows = [row + ",text" for row in rows]
    elif kind == 11:  # rows cut to a few
        rows = rows[: int(rng.integers(0, 40))]
    elif kind == 12:  # Windows line ends and a byte-order mark
        return ("\ufeff" + header + "\r\n" + "\r\n".join(rows) + "\r\n").encode()
    elif kind == 13:  # time reversed or jittered
        ts = [row.split(",", 1) for row in rows]
        if rng.random() < 0.5:
            rows = [f"{a[0]},{b[1]}" for a, b in zip(reversed(ts), ts, strict=True)]
        else:
            rows = [f"{float(t) + float(rng.normal(0, 1e-3)):.17g},{rest}" for t, rest in ts]
    elif kind == 14:  # many cells replaced
        for _ in range(int(rng.integers(2, 30))):
            rr = int(rng.integers(len(rows)))
            cs = rows[rr].split(",")
            cs[int(rng.integers(len(cs)))] = TOKENS[int(rng.integers(len(TOKENS)))]
            rows[rr] = ",".join(cs)
    elif kind == 15:  # columns dropped (angles only, or less)
        keep = [j for j in range(len(header.split(","))) if rng.random() < 0.6 or j == 0]
        header = ",".join(header.split(",")[j] for j in keep)
        rows = [",".join(row.split(",")[j] for j in keep) for row in rows]
    elif kind == 16:  # the time in microseconds (alone, or with every rate)
        ts = [row.split(",") for row in rows]
        scale_rates = rng.random() < 0.5
        rows = [",".join([repr(float(v[0]) * 1e6), v[1], *(repr(float(x) * (1e-6 if scale_rates else 1.0))
                                                            for x in v[2:])]) for v in ts]
    else:  # quotes around a cell
        cells[c] = f'"{cells[c]}"'
        rows[r] = ",".join(cells)
    return (header + "\n" + "\n".join(rows) + "\n").encode()


def _finite_outputs(comp) -> list[str]:
    values = {"rms": comp.rms, "r2": comp.r2, "fit_percent": comp.fit_percent, **comp.physical,
              **dict(zip(comp.columns, comp.coefficients, strict=True)),
              **{f"se {c}": v for c, v in zip(comp.columns, comp.standard_errors, strict=True)}}
    return [k for k, v in values.items() if not math.isfinite(float(v))]


def test_fuzzed_csv_files(tmp_path, valid_csv):
    rng = np.random.default_rng(SEED)
    load_measurements_ok = fitted = refused = 0
    previous = signal.signal(signal.SIGALRM, _alarm)
    fit(load_measurements(_write(tmp_path / "warm.csv", valid_csv)), MODEL)  # compile outside the budget
    started = time.perf_counter()
    try:
        for case in range(CASES):
            data = _mutate(rng, valid_csv)
            path = _write(tmp_path / f"case{case}.csv", data)
            signal.setitimer(signal.ITIMER_REAL, BUDGET)
            try:
                try:
                    meas = load_measurements(path)
                except MeasurementError as exc:
                    refused += 1
                    _check_message(str(exc), case, data)
                    continue
                load_measurements_ok += 1
                try:
                    comp = fit(meas, MODEL)
                except (SimulationError, ValueError) as exc:  # MeasurementError, SimulationTooLarge too
                    assert type(exc).__module__.split(".")[0] in ("rotor_env", "identifier", "builtins"), \
                        (case, type(exc), exc)
                    _check_message(str(exc), case, data)
                    continue
                bad = _finite_outputs(comp)
                assert not bad, f"case {case}: silent non-finite output {bad}"
                fitted += 1
            except Hang:
                pytest.fail(f"case {case}: no answer within {BUDGET} s (a hang)\n{data[:300]!r}")
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
                path.unlink()
    finally:
        signal.signal(signal.SIGALRM, previous)
    # the mutations reach every stage: refused on load, loaded and fitted
    assert refused > CASES // 4 and fitted > CASES // 10, (refused, load_measurements_ok, fitted)
    assert time.perf_counter() - started < 60


def _check_message(msg: str, case: int, data: bytes) -> None:
    assert msg and "np.float64" not in msg and "Traceback" not in msg, (case, msg)
    assert "nan" not in msg.split(":")[-1].lower() or "nan" in data.decode("utf-8", "replace").lower(), (case, msg)


def _write(path, data: bytes):
    path.write_bytes(data)
    return path
