"""Reading measurement files (CSV, Parquet) with validation that names the problem.

CSV files are read in the dialect their first lines show (:func:`csv_dialect`): fields
separated by commas, semicolons or tabs, and with semicolons or tabs the decimal comma of a
European locale (``0,0001;-4,654``: what spreadsheet and acquisition software write there).

Required columns: ``t``, ``phi``, ``theta_x``, ``theta_y``.  Rates and accelerations
(``phi_dot``, ``phi_ddot``, ``theta_x_dot``, ``theta_y_dot``, ``theta_x_ddot``,
``theta_y_ddot``) are used when present; any that are missing are estimated from the
angles by a Savitzky–Golay filter (local polynomial of order 5 over a window of about
0.2 time units, i.e. 21 samples at ``dt = 0.01``).  Accuracy measured on the simulated
Table-1 run (noise-free, ``dt = 0.01``, all samples), relative to each channel's peak:
rates within 6e-6 at worst (RMS 4e-8) and accelerations within 1.2e-3 at worst (RMS
7e-6).  The worst case is where the dry friction lets go (t ~ 85: a kink in the rate,
a jump in the acceleration) and the last 0.2 time units of the record (up to 1.7e-4);
elsewhere accelerations are within 1.5e-5 and rates within 2e-8 (see
``tests/test_io.py``).  Noise on the angles is amplified by differentiation: prefer
measured rates when you have them.

Every error names the file, and where it applies the column and the (1-based) line
of the file (the header is line 1).
"""

from __future__ import annotations

import array
import csv
import difflib
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import savgol_filter

from .core import COLUMNS, Measurements

__all__ = [
    "REQUIRED",
    "CsvDialect",
    "MeasurementError",
    "PhiUnwrapper",
    "check_finite",
    "check_header",
    "check_tilt",
    "check_time",
    "csv_dialect",
    "derive_rates",
    "dialect_of_lines",
    "first_step",
    "load_measurements",
    "read_table",
    "restore_rounded_time",
    "table_header",
]

REQUIRED: tuple[str, ...] = ("t", "phi", "theta_x", "theta_y")
#: derived column -> (source column, derivative order)
DERIVABLE: dict[str, tuple[str, int]] = {
    "phi_dot": ("phi", 1),
    "phi_ddot": ("phi", 2),
    "theta_x_dot": ("theta_x", 1),
    "theta_y_dot": ("theta_y", 1),
    "theta_x_ddot": ("theta_x", 2),
    "theta_y_ddot": ("theta_y", 2),
}
MIN_ROWS = 20
#: relative tolerance on the spacing of ``t``
UNIFORM_RTOL = 1e-3
#: a measurement cell beyond this is no measurement: squares and products of it overflow
MAX_ABS = 1e30


class MeasurementError(ValueError):
    """A measurement file that cannot be used as it is."""


# ------------------------------------------------------------------ validation
# One validation for every reader: a whole file (load_measurements, a rig's waveforms), a
# stream read in chunks (measurements.stream, measurements.rig_stream) and the monitor's
# arrays.  A refused row raises ``error`` with ``.row``, its index in the rows given, and
# a message that names the source, the file line (``lines``; without them "row r of
# SOURCE"), the column and the value.
def _where(source, lines, r: int) -> str:
    return f"{source}, line {lines[r]}" if lines is not None else f"row {r} of {source}"


def _refuse(error: type[Exception], message: str, row: int) -> Exception:
    exc = error(message)
    exc.row = row
    return exc


def check_header(source, header: Sequence[str], *, required: Sequence[str] = REQUIRED,
                 missing_hint: str | None = None) -> None:
    """Every name once and every ``required`` column there (a model column's likely
    misspelling named); ``missing_hint``: where the required names come from, said instead."""
    dup = {h for h in header if header.count(h) > 1}
    if dup:
        raise MeasurementError(f"{source}: column(s) {sorted(dup)} appear more than once")
    missing = [c for c in required if c not in header]
    if missing and missing_hint is not None:
        raise MeasurementError(f"{source}: column(s) {missing} {missing_hint} are not in the stream "
                               f"(its header has {_cut(list(header), 300)})")
    if missing:
        hints = []
        for m in missing:
            close = difflib.get_close_matches(m, [h for h in header if h not in COLUMNS], n=1, cutoff=0.6)
            hints.append(f"{m!r}" + (f" (found {close[0]!r}: misspelt?)" if close else ""))
        raise MeasurementError(
            f"{source}: missing required column(s) {', '.join(hints)}; "
            f"the file has {_cut(list(header), 400)}; required: {list(REQUIRED)}, optional: {list(DERIVABLE)}"
        )


def check_finite(source, data: np.ndarray, names: Sequence[str], lines=None, *, max_abs: float = MAX_ABS,
                 error: type[Exception] = MeasurementError) -> None:
    """Every value of ``data`` (columns ``names``) finite and within ``max_abs`` (beyond it
    the model's products of it overflow)."""
    bad = ~np.isfinite(data)
    if bad.any():
        r, c = (int(i) for i in np.argwhere(bad)[0])
        raise _refuse(error, f"{_where(source, lines, r)}, column {names[c]!r}: value {_num(data[r, c])} is not "
                             "finite", r)
    big = np.abs(data) > max_abs
    if big.any():
        r, c = (int(i) for i in np.argwhere(big)[0])
        raise _refuse(error, f"{_where(source, lines, r)}, column {names[c]!r}: value {_num(data[r, c])} is beyond "
                             f"{max_abs:g}: not a measurement (the model's products of it overflow)", r)


def check_time(source, t: np.ndarray, lines=None, *, step: float | None = None, previous: float = math.nan,
               column: str = "t", unit: str = "", error: type[Exception] = MeasurementError) -> float:
    """Times that increase at a uniform ``step`` (within :data:`UNIFORM_RTOL`; ``None``: the
    median step of ``t``) after ``previous`` (the last time of the chunk before, if any).
    Returns the step; ``unit`` (" s") is written after the times."""
    t = np.asarray(t, dtype=float)
    shift = 0 if math.isnan(previous) else 1
    tt = t if not shift else np.concatenate([[previous], t])
    diff = np.diff(tt)
    if not diff.size:
        return 0.0 if step is None else step
    if (diff <= 0).any():
        j = int(np.argmax(diff <= 0))
        r = j + 1 - shift
        raise _refuse(error, f"{_where(source, lines, r)}, column {column!r}: time {_num(tt[j + 1])}{unit} does not "
                             f"increase (previous {_num(tt[j])}{unit})", r)
    step = float(np.median(diff)) if not step else step
    off = np.abs(diff - step) > UNIFORM_RTOL * step
    if off.any():
        j = int(np.argmax(off))
        r = j + 1 - shift
        raise _refuse(error, f"{_where(source, lines, r)}, column {column!r}: non-uniform sampling: step "
                             f"{_num(diff[j])}{unit} where the record's step is {_num(step)}{unit} (samples missing?)",
                      r)
    return step


def _decimal_quantum(t: np.ndarray) -> float | None:
    """The resolution the times were written with: the largest ``10^-d`` (d = 0..12) of which
    every time is a whole multiple (to 1e-6 of it); ``None`` where none is."""
    for d in range(13):
        s = t * 10.0**d
        if np.all(np.abs(s - np.round(s)) <= 1e-6):
            return 10.0**-d
    return None


def restore_rounded_time(t: np.ndarray, unit: str = "") -> tuple[np.ndarray, str]:
    """Times written with too few decimals for their step (51.2 kHz, ``dt`` = 19.53125 us,
    written to the microsecond: steps of 19 and 20 us) -> the uniform grid they were rounded
    from, and a note; ``t`` itself and ``""`` where they are uniform already, or are not such
    a grid: every time within half the written resolution of the least-squares line through
    them, and that resolution under half a step (a missing sample, a jump, stays an error of
    :func:`check_time`)."""
    t = np.asarray(t, dtype=float)
    diff = np.diff(t)
    if diff.size < 2 or not (diff > 0).all():
        return t, ""
    step = float(np.median(diff))
    if not (np.abs(diff - step) > UNIFORM_RTOL * step).any():
        return t, ""
    q = _decimal_quantum(t)
    if q is None:
        return t, ""
    k = np.arange(t.size, dtype=float)
    dt, t0 = np.polyfit(k, t, 1)
    grid = t0 + k * dt
    # half the resolution, and a hair for the line's own error at a tie (x.5 rounded); a
    # missing sample puts the line half a step off, more than that since q < step / 2
    tol = 0.51 * q
    if not (q < 0.5 * dt and float(np.max(np.abs(t - grid))) <= tol):
        return t, ""
    rate = f", {1.0 / dt:.6g} Hz" if unit.strip() == "s" else ""
    return grid, (f"the times are written to {q:g}{unit} for a step of {dt:.6g}{unit}{rate}: read as the uniform "
                  f"grid they were rounded from (each within half of {q:g}{unit})")


def first_step(t: np.ndarray, previous: float = math.nan) -> float:
    """A stream's step: its first (from ``previous``, the last time before, if any; the batch
    reader's derivatives take that one too), 0.0 while there is none."""
    tt = np.asarray(t, dtype=float) if math.isnan(previous) else np.concatenate([[previous], t])
    return float(tt[1] - tt[0]) if tt.size > 1 and tt[1] > tt[0] else 0.0


def check_tilt(source, data: np.ndarray, names: Sequence[str], lines=None) -> None:
    """Inclinations (columns ``names`` of ``data``) within :data:`MAX_TILT` rad: beyond, degrees."""
    big = np.abs(data) > MAX_TILT
    if big.any():
        r, c = (int(i) for i in np.argwhere(big)[0])
        raise _refuse(MeasurementError, f"{_where(source, lines, r)}, column {names[c]!r}: value {_num(data[r, c])} "
                                        f"is beyond {MAX_TILT:g} rad ({math.degrees(MAX_TILT):.0f} deg), not a shaft's "
                                        "tilt: degrees? (inclinations are in radians)", r)


class PhiUnwrapper:
    """An encoder's spin angle ``phi`` unwrapped chunk by chunk; degrees and aliasing refused.

    The rule: a sampled spin angle never moves by more than pi between two samples (it would
    alias), so a jump beyond pi while every value seen stays within one turn's span (2 pi)
    is a wrap, an encoder's [0, 2 pi) or (-pi, pi], and is undone by whole turns (as
    :func:`numpy.unwrap`).  A jump beyond pi once the values span more than a turn is refused,
    naming the line after it: "wrapped to 360" (degrees) when they span at most 360 and a
    step exceeds 300, "jumps from ... (more than half a turn ...)" otherwise.

    The one implementation for every reader: :func:`load_measurements` pushes the whole
    column once (the span is the column's), :class:`~rotor_env.measurements.stream.StreamReader`
    pushes chunk after chunk (the span is that of every value seen so far; the last value
    of a chunk is the one before the next).  :meth:`push` returns ``phi + 2 pi k`` with
    ``k`` whole turns, so the result does not depend on how the column is cut into chunks.
    ``unwrapped`` says whether a wrap was undone.
    """

    __slots__ = ("_last", "_max", "_min", "_turns", "source", "unwrapped")

    def __init__(self, source) -> None:
        self.source = source
        self.unwrapped = False
        self._last = math.nan
        self._min = math.inf
        self._max = -math.inf
        self._turns = 0.0

    def push(self, phi: np.ndarray, lines=None) -> np.ndarray:
        """The next chunk of ``phi`` (file ``lines``), unwrapped.  A refused chunk raises
        :class:`MeasurementError` with ``.row``, the index in the chunk of the row after the
        jump, and leaves the state as it was: the rows before that one can be pushed again."""
        phi = np.asarray(phi, dtype=float)
        if not phi.size:
            return phi
        shift = 0 if math.isnan(self._last) else 1
        raw = phi if not shift else np.concatenate([[self._last], phi])
        steps = np.diff(raw)
        jumps = np.abs(steps) > math.pi
        lo, hi = min(self._min, float(phi.min())), max(self._max, float(phi.max()))
        if not jumps.any():
            out = phi if not self._turns else phi + 2 * math.pi * self._turns
        else:
            j = int(np.argmax(jumps))
            r = j + 1 - shift
            if hi - lo > 2 * math.pi + 1e-6:
                where = f"{_where(self.source, lines, r)}, column 'phi'"
                if hi - lo <= 360.0 + 1e-6 and float(np.max(np.abs(steps))) > 300.0:
                    raise _refuse(MeasurementError, f"{where}: wrapped to 360 ({_num(raw[j])} -> {_num(raw[j + 1])}): "
                                                    "the spin angle is in degrees; convert it to radians", r)
                raise _refuse(MeasurementError, f"{where}: jumps from {_num(raw[j])} to {_num(raw[j + 1])} between "
                                                "two samples (more than half a turn: the angle is aliased or not "
                                                "in radians)", r)
            # whole turns back at every wrap (within one turn's span a step is at most 2 pi)
            back = np.where(jumps, -np.sign(steps) * np.floor(np.abs(steps) / (2 * math.pi) + 0.5), 0.0)
            turns = self._turns + np.concatenate([[0.0], np.cumsum(back)])[shift:]  # of every row of phi
            out = phi + 2 * math.pi * turns
            self._turns = float(turns[-1])
            self.unwrapped = True
        self._min, self._max = lo, hi
        self._last = float(phi[-1])
        return out


@dataclass(frozen=True)
class CsvDialect:
    """How a CSV file writes its fields: the separator and the decimal mark."""

    delimiter: str = ","
    decimal: str = "."

    def number(self, cell: str) -> float:
        """A cell's number (``ValueError`` where it is none)."""
        return float(cell.replace(",", ".") if self.decimal == "," else cell)


#: the field separators a CSV file is read with (the first that splits the header most wins)
CSV_DELIMITERS = (",", ";", "\t")
#: lines read to tell the dialect (the header and the first data lines)
DIALECT_LINES = 32
#: a number written with a decimal comma: ``-4,654``, ``1,5e-3``
_DECIMAL_COMMA = re.compile(r"[+-]?\d+,\d+(?:[eE][+-]?\d+)?")


def csv_dialect(path: str | os.PathLike) -> CsvDialect:
    """The dialect of a CSV file (:func:`dialect_of_lines` on its first lines); a file that
    cannot be read as text gets the default (the reader's own error then names what is wrong)."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            return dialect_of_lines([fh.readline() for _ in range(DIALECT_LINES)])
    except (OSError, UnicodeDecodeError):
        return CsvDialect()


def dialect_of_lines(lines: Sequence[str]) -> CsvDialect:
    """The dialect of a CSV text from its header and first data lines: the separator of
    :data:`CSV_DELIMITERS` that splits them all into the same, largest number of fields (a
    comma where none splits them), and a decimal comma where the separator is not a comma and
    those lines write a number with a comma and none with a point."""
    lines = [ln.rstrip("\r\n") for ln in lines if ln.strip()]
    best, fields, rows = ",", 1, []
    for d in CSV_DELIMITERS:
        try:
            split = [next(csv.reader([ln], delimiter=d)) for ln in lines]
        except csv.Error:
            continue
        if split and len(split[0]) > fields and all(len(r) == len(split[0]) for r in split):
            best, fields, rows = d, len(split[0]), split[1:]
    cells = [c.strip() for r in rows for c in r]
    comma = any(_DECIMAL_COMMA.fullmatch(c) for c in cells)
    point = any("." in c for c in cells)
    return CsvDialect(best, "," if best != "," and comma and not point else ".")


def table_header(path: str | os.PathLike) -> list[str]:
    """The column names of a CSV (in its dialect) or Parquet file, stripped; ``[]`` where the
    file cannot be read (:func:`read_table` then names what is wrong)."""
    path = Path(path)
    try:
        if path.suffix == ".parquet":
            import pyarrow.parquet as pq

            return [str(n).strip() for n in pq.read_schema(path).names]
        with open(path, encoding="utf-8-sig", newline="") as fh:
            lines = [fh.readline() for _ in range(DIALECT_LINES)]
        dialect = dialect_of_lines(lines)
        return [h.strip() for h in next(csv.reader([lines[0].rstrip("\r\n")], delimiter=dialect.delimiter))]
    except Exception:  # any unreadable file: the reader's own error follows
        return []


def read_table(path: str | os.PathLike, *, numeric: Sequence[str] | None = None
               ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Header, float data and the file line number of every data row of a CSV or Parquet file.

    ``lines[r]`` is the 1-based line of data row ``r`` in the file (the header is line
    1, blank lines are skipped; for Parquet, row ``r`` is "line" ``r + 2``).  Every
    column must be numeric, unless ``numeric`` names the columns that must be: any other
    column that is not (a text note, a label) is read as NaN — the caller ignores it.
    Errors are :class:`MeasurementError` naming the file, line, column and value.
    A timestamp/date column is refused (time is a number in the model's unit).  A CSV file
    is read in its own dialect (:func:`csv_dialect`).
    """
    path = Path(path)
    if path.suffix == ".parquet":
        return _read_parquet(path, numeric)
    return _read_csv(path, numeric)


def _read_csv(path: Path, numeric: Sequence[str] | None = None) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Header, data and the file line number of every data row (blank lines are skipped).

    pyarrow's CSV reader first (multi-threaded, 8 bytes a value); a file it cannot take
    as it is (a bad cell, a blank line, a wrong field count: anything unusual) is read
    again by the line-by-line parser, whose errors name the line, column and value.
    """
    dialect = csv_dialect(path)
    fast = _read_csv_arrow(path, numeric, dialect)
    if fast is not None:
        return fast
    try:
        # utf-8-sig: a byte-order mark (Excel's "CSV UTF-8") is not part of the first name
        with open(path, newline="", encoding="utf-8-sig") as fh:
            return _parse_csv(path, csv.reader(fh, delimiter=dialect.delimiter), numeric, dialect)
    except UnicodeDecodeError as exc:
        raise MeasurementError(
            f"{path}: not a text (UTF-8) CSV file ({exc.reason} at byte {exc.start}); "
            "Parquet files must end in .parquet"
        ) from None
    except csv.Error as exc:
        raise MeasurementError(f"{path}: not a readable CSV file ({exc})") from None
    except OSError as exc:
        raise MeasurementError(f"{path}: cannot read the file ({exc.strerror or exc})") from None


def _read_csv_arrow(path: Path, numeric: Sequence[str] | None, dialect: CsvDialect | None = None):
    """The fast path: ``None`` unless the file is clean (no blank line, null or odd cell);
    ``dialect``: the file's (read off it when not given)."""
    dialect = csv_dialect(path) if dialect is None else dialect
    try:
        import pyarrow as pa
        import pyarrow.csv as pc
    except ImportError:  # pragma: no cover - pyarrow is a dependency
        return None
    try:
        with open(path, "rb") as fh:
            first = fh.readline()
        names = [h.strip() for h in next(csv.reader([first.decode("utf-8-sig")], delimiter=dialect.delimiter))]
    except (OSError, UnicodeDecodeError, csv.Error, StopIteration):
        return None  # the careful parser says what is wrong
    if not names or len(set(names)) != len(names):
        return None
    want = set(names) if numeric is None else set(numeric)
    try:
        table = pc.read_csv(
            path,
            read_options=pc.ReadOptions(column_names=names, skip_rows=1),
            parse_options=pc.ParseOptions(delimiter=dialect.delimiter, ignore_empty_lines=False),
            convert_options=pc.ConvertOptions(column_types={n: pa.float64() for n in names if n in want},
                                              decimal_point=dialect.decimal),
        )
    except (pa.ArrowException, OSError, ValueError):
        return None
    m = table.num_rows
    data = np.empty((m, len(names)))
    for j, name in enumerate(names):
        col = table.column(j)
        if pa.types.is_floating(col.type) or pa.types.is_integer(col.type):
            if col.null_count:
                return None  # an empty cell, a blank line or "nan": the careful parser names it
            data[:, j] = col.to_numpy()
        elif name in want:
            return None
        else:
            data[:, j] = np.nan  # a column the caller does not need and that is not numeric
    del table
    return names, data, np.arange(m, dtype=np.int64) + 2


def _parse_csv(path: Path, reader, numeric: Sequence[str] | None = None, dialect: CsvDialect = CsvDialect()
               ) -> tuple[list[str], np.ndarray, np.ndarray]:
    try:
        header = next(reader)
    except StopIteration:
        raise MeasurementError(f"{path}: the file is empty (expected a header line)") from None
    header = [h.strip() for h in header]
    need = [numeric is None or h in numeric for h in header]
    values = array.array("d")  # 8 bytes a value (lists of floats took 3.3 GB for 5 M rows)
    lines = array.array("q")
    for row in reader:
        line_no = reader.line_num
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise MeasurementError(
                f"{path}, line {line_no}: {len(row)} fields, but the header has {len(header)}"
            )
        for name, cell, required in zip(header, row, need, strict=True):
            try:
                values.append(dialect.number(cell))
            except ValueError:
                if not required:
                    values.append(math.nan)
                    continue
                hint = ("" if dialect.decimal == "," or not _DECIMAL_COMMA.fullmatch(cell.strip()) else
                        " (a decimal comma where the file's first lines write none: write every number alike)")
                raise MeasurementError(
                    f"{path}, line {line_no}, column {_cut(name)}: {_cut(cell.strip())} is not a number{hint}"
                ) from None
        lines.append(line_no)
    data = np.frombuffer(values, dtype=float).reshape(len(lines), len(header)).copy()
    return header, data, np.frombuffer(lines, dtype=np.int64).copy()


def _read_parquet(path: Path, numeric: Sequence[str] | None = None) -> tuple[list[str], np.ndarray, np.ndarray]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except Exception as exc:
        raise MeasurementError(f"{path}: not a readable Parquet file ({exc})") from None
    header = list(table.column_names)
    data = np.empty((table.num_rows, len(header)))
    for j, name in enumerate(header):
        col = table.column(j)
        kind = col.type
        if pa.types.is_timestamp(kind) or pa.types.is_date(kind) or pa.types.is_time(kind) \
                or pa.types.is_duration(kind):
            if numeric is not None and name not in numeric:
                data[:, j] = np.nan
                continue
            raise MeasurementError(
                f"{path}, column {name!r}: a {kind} column, not a number: give the time as a number "
                "(the model's dimensionless time, or seconds from the start: the diagnosis rescales it)"
            )
        try:
            data[:, j] = np.asarray(col.to_numpy(zero_copy_only=False), dtype=float)
        except (TypeError, ValueError, pa.ArrowException):
            if numeric is not None and name not in numeric:
                data[:, j] = np.nan  # a text column the caller ignores
                continue
            raise MeasurementError(f"{path}, column {name!r}: not numeric ({kind})") from None
    # "line" of row r: r + 2, as if the table were a CSV file with a header line
    return header, data, np.arange(data.shape[0], dtype=np.int64) + 2


def derive_rates(t: np.ndarray, x: np.ndarray, order: int, window: float = 0.2) -> np.ndarray:
    """Derivative of ``x`` (order 1 or 2) by a Savitzky–Golay filter of polynomial order 5."""
    dt = float(t[1] - t[0])
    n = max(7, round(window / dt))
    n += 1 - n % 2  # odd
    n = min(n, len(x) - (1 - len(x) % 2))
    poly = min(5, n - 1)
    return savgol_filter(x, n, poly, deriv=order, delta=dt, mode="interp")


def load_measurements(path: str | os.PathLike, *, min_rows: int = MIN_ROWS) -> Measurements:
    """Read and validate a measurement file; estimate missing rates/accelerations."""
    path = Path(path)
    if not path.exists():
        raise MeasurementError(f"{path}: no such file")
    if path.is_dir():
        raise MeasurementError(f"{path}: is a directory, not a measurement file")
    header, data, lines = read_table(path, numeric=COLUMNS)
    check_header(path, header)
    unknown = [h for h in header if h not in COLUMNS]
    if unknown:
        close = {u: difflib.get_close_matches(u, COLUMNS, n=1, cutoff=0.75) for u in unknown}
        misspelt = {u: c[0] for u, c in close.items() if c and c[0] not in header}
        if misspelt:
            u, c = next(iter(misspelt.items()))
            raise MeasurementError(f"{path}: unknown column {u!r} — did you mean {c!r}?")
    notes: list[str] = []
    if unknown:
        text = [u for u in unknown if np.isnan(data[:, header.index(u)]).all() and data.shape[0]]
        notes.append(f"ignored column(s) {', '.join(map(repr, unknown))}"
                     + (f" ({', '.join(map(repr, text))} not numeric)" if text else "") + ": not model columns")
    if data.shape[0] == 0:
        raise MeasurementError(f"{path}: the file has a header but no data rows")
    if data.shape[0] < min_rows:
        raise MeasurementError(f"{path}: only {data.shape[0]} data rows; at least {min_rows} are needed")
    idx = {h: i for i, h in enumerate(header)}
    present = [c for c in COLUMNS if c in idx]
    check_finite(path, data[:, [idx[c] for c in present]], present, lines)
    t, rounded = restore_rounded_time(data[:, idx["t"]])
    if rounded:
        data[:, idx["t"]] = t
        notes.append(rounded)
    check_time(path, t, lines)
    out = np.empty((data.shape[0], len(COLUMNS)))
    for j, c in enumerate(COLUMNS):
        if c in idx:
            out[:, j] = data[:, idx[c]]
    notes += _check_units(path, out, idx, lines)
    _check_rates(path, out, idx)
    if data.shape[0] > LARGE_RECORD:
        notes.append(f"{data.shape[0]} samples: a diagnosis costs about {data.shape[0] * DIAGNOSE_S_PER_SAMPLE / 60:.0f} "
                     "min (decimate the record to speed it up)")
    for c, (src, order) in DERIVABLE.items():
        if c not in idx:
            out[:, COLUMNS.index(c)] = derive_rates(t, out[:, COLUMNS.index(src)], order)
    derived = [c for c in DERIVABLE if c not in idx]
    if derived:
        notes.append(f"estimated: {', '.join(derived)}")
    note = f" ({'; '.join(notes)})" if notes else ""
    return Measurements(out, source=f"{path}{note}", estimated=tuple(derived))


#: records longer than this get a note with what a diagnosis of them costs
LARGE_RECORD = 1_000_000
#: a diagnosis's cost per sample (measured: 40 001 samples in ~4.5 s, 5 M in ~560 s)
DIAGNOSE_S_PER_SAMPLE = 1.1e-4


def _cut(x, chars: int = 80) -> str:
    """``repr(x)`` cut short: a hostile file's value is never echoed whole into a message."""
    text = repr(x)
    return text if len(text) <= chars else text[: chars - 20] + f"... ({len(text)} chars)"


def _num(x) -> str:
    """A number as a user reads it: ``50.01``, not ``np.float64(50.01)``."""
    return repr(float(x))


def _check_rates(path: Path, out: np.ndarray, idx: dict) -> None:
    """Measured inclination rates must be the rates of the angles in the time unit of ``t``.

    A time column in another unit than the rates (microseconds beside rates per model
    time unit) makes every derivative wrong by that factor, and the model's free run
    would take that many more integration steps: refused with the factor named.
    """
    t = out[:, 0]
    for ang, rate in (("theta_x", "theta_x_dot"), ("theta_y", "theta_y_dot"), ("phi_dot", "phi_ddot")):
        if rate not in idx or ang not in idx:
            continue
        x = out[:, COLUMNS.index(ang)]
        given = out[:, COLUMNS.index(rate)]
        num = np.gradient(x, t)
        gg = float(given @ given)
        if not (gg > 0 and np.isfinite(gg)) or len(t) < 10:
            continue
        ratio = float(num @ given) / gg
        # the slope only speaks when the angle's own rate explains it (not noise, not aliased)
        fit = np.linalg.norm(num - ratio * given) < 0.5 * np.linalg.norm(num)
        if fit and not (1.0 / RATE_MISMATCH < abs(ratio) < RATE_MISMATCH):
            raise MeasurementError(
                f"{path}, column {rate!r}: the rate of column {ang!r} over 't' is {ratio:.4g}x this column: "
                "'t' and the rates are in different time units (time in microseconds or milliseconds?); "
                "give every column in one time unit"
            )


#: an inclination beyond this (1 rad, 57 deg) is not a shaft's tilt: degrees, or another quantity
MAX_TILT = 1.0
#: a spin angle whose rate disagrees with phi_dot by this factor or more is in another unit
RATE_MISMATCH = 3.0


def _check_units(path: Path, out: np.ndarray, idx: dict, lines) -> list[str]:
    """Plausibility of the angle columns (in place: a wrapped ``phi`` is unwrapped).

    An encoder reports ``phi`` wrapped to [0, 2 pi) or (-pi, pi]: a sampled spin angle
    never moves by more than pi between samples (that would alias), so jumps beyond pi in
    a column that stays within one turn are wraps, and are undone (:class:`PhiUnwrapper`,
    given the whole column).  Degrees are refused with the column named: ``phi`` whose
    rate is 57x ``phi_dot``, or wrapped to [0, 360); inclinations beyond 1 rad.
    """
    notes: list[str] = []
    j_phi = COLUMNS.index("phi")
    t = out[:, 0]
    phi = PhiUnwrapper(path)
    out[:, j_phi] = phi.push(out[:, j_phi], lines)
    if phi.unwrapped:
        notes.append("phi unwrapped (it was wrapped to one turn)")
    if "phi_dot" in idx:
        rate = np.gradient(out[:, j_phi], t)
        given = out[:, COLUMNS.index("phi_dot")]
        moving = np.abs(given) > 0.05 * max(float(np.max(np.abs(given))), 1e-300)
        if moving.sum() > 10:
            ratio = float(np.median(rate[moving] / given[moving]))
            if not (1.0 / RATE_MISMATCH < abs(ratio) < RATE_MISMATCH):
                unit = " (degrees: 57.3)" if abs(abs(ratio) - 180.0 / math.pi) < 5.0 else ""
                raise MeasurementError(f"{path}, column 'phi': its rate is {ratio:.4g}x column 'phi_dot'{unit}: "
                                       "phi must be in radians and phi_dot in radians per time unit of 't'")
    check_tilt(path, out[:, [COLUMNS.index("theta_x"), COLUMNS.index("theta_y")]], ("theta_x", "theta_y"), lines)
    return notes
