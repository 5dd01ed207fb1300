"""Measurement streams read in chunks: a file, a file being appended (``--follow``), stdin.

The formats are :func:`rotor_env.measurements.files.load_measurements`' (CSV with a header line, or
Parquet; required ``t, phi, theta_x, theta_y``, rates and accelerations optional) and so
are the errors: they name the source, the (1-based) line and the column.  Nothing is
loaded whole: CSV text is read in blocks of bytes, only complete lines are parsed
(pyarrow's CSV parser on the block; on a parse error the block is read again line by
line to name the bad one), Parquet row batch by row batch.  :meth:`StreamReader.blocks`
hands out the raw file columns (the rig adapter, :mod:`.rig_stream`, reads SI waveforms
through it); iterating the reader validates them as the model's ten columns.

Missing rates and accelerations are estimated as ``load_measurements`` does
(Savitzky-Golay, :func:`rotor_env.measurements.files.derive_rates`), on a sliding buffer: a sample's
derivative needs half a window of samples after it, so those are held back until they
arrive (or the stream ends).  An encoder's ``phi`` wrapped to one turn is unwrapped across
chunks (:class:`~rotor_env.measurements.files.PhiUnwrapper`, as the batch reader does).
"""

from __future__ import annotations

import csv
import io
import math
import queue
import select
import sys
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np
from scipy.signal import savgol_filter

from .core import COLUMNS
from .files import (
    DERIVABLE,
    DIALECT_LINES,
    REQUIRED,
    CsvDialect,
    MeasurementError,
    PhiUnwrapper,
    check_finite,
    check_header,
    check_tilt,
    check_time,
    dialect_of_lines,
    first_step,
)

__all__ = ["StreamReader", "iter_chunks", "read_ahead"]

CHUNK_BYTES = 1 << 20
#: a row of the stream longer than this is refused (its columns are a few numbers)
MAX_LINE_BYTES = 1 << 16


class StreamReader:
    """Chunks of ``(m, 10)`` samples from a CSV/Parquet file, a followed file, or stdin.

    ``source``: a path, ``"-"`` (standard input) or a binary file object.  ``follow``:
    at the end of the data wait for more (``poll`` seconds between looks) until
    ``idle_exit`` seconds pass without any (``None``: forever).  ``line`` is the file
    line of the last row handed out.  ``required``: the columns the header must have
    (default the model's; ``missing_hint`` then says where the names come from).
    """

    def __init__(self, source, *, follow: bool = False, poll: float = 0.2, idle_exit: float | None = None,
                 chunk_bytes: int = CHUNK_BYTES, required: Sequence[str] = REQUIRED,
                 missing_hint: str | None = None) -> None:
        self.required = tuple(required)
        self.missing_hint = missing_hint
        self.follow = follow
        self.poll = poll
        self.idle_exit = idle_exit
        self.chunk_bytes = int(chunk_bytes)
        if isinstance(source, (str, Path)) and str(source) == "-":
            self.name = "<stdin>"
            self._fh: BinaryIO | None = sys.stdin.buffer
            self._path = None
        elif isinstance(source, (str, Path)):
            self._path = Path(source)
            self.name = str(source)
            if not self._path.exists():
                raise MeasurementError(f"{self._path}: no such file")
            if self._path.is_dir():
                raise MeasurementError(f"{self._path}: is a directory, not a measurement file")
            self._fh = None
        else:
            self.name = getattr(source, "name", "<stream>")
            self._fh = source
            self._path = None
        self.line = 1
        #: the CSV dialect, read off the stream's first lines (:func:`~.files.dialect_of_lines`)
        self._dialect = CsvDialect()
        self.error_line: int | None = None
        self._last_t = math.nan
        self._dt = 0.0
        self._phi = PhiUnwrapper(self.name)
        self._deriv: SlidingDerivatives | None = None

    # ------------------------------------------------------------------ chunks
    def __iter__(self) -> Iterator[np.ndarray]:
        for parsed in self.blocks():
            yield from self._emit(parsed)
        yield from self._emit(None)

    def blocks(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Raw blocks ``(data in the file's columns, file line of each row)``, header in
        :attr:`header`; at a bad line the rows before it come first, then the error."""
        if self._path is not None and self._path.suffix == ".parquet":
            yield from self._parquet()
            return
        fh = self._fh if self._fh is not None else open(self._path, "rb")
        try:
            yield from self._csv(fh)
        finally:
            if self._fh is None:
                fh.close()

    @property
    def header(self) -> list[str]:
        """The stream's column names (known once the first block is out)."""
        return list(self._header_names)

    def _read(self, fh: BinaryIO) -> bytes:
        """What is there now, up to ``chunk_bytes``: a pipe hands out 64 KiB per read, so keep
        reading while more is ready (never waiting: a live source must not be held up)."""
        read1 = getattr(fh, "read1", None)
        if read1 is None:
            return fh.read(self.chunk_bytes)
        out = read1(self.chunk_bytes)
        try:
            fd = fh.fileno()
        except (OSError, ValueError, io.UnsupportedOperation):
            return out
        parts = [out]
        size = len(out)
        while out and size < self.chunk_bytes and select.select([fd], [], [], 0)[0]:
            out = read1(self.chunk_bytes - size)
            parts.append(out)
            size += len(out)
        return b"".join(parts)

    def _more(self, fh: BinaryIO) -> Iterator[bytes]:
        """Blocks of bytes; with ``follow``, waits at the end for the file to grow."""
        idle_since = time.monotonic()
        while True:
            data = self._read(fh)
            if data:
                idle_since = time.monotonic()
                yield data
                continue
            if not self.follow or (self.idle_exit is not None and time.monotonic() - idle_since > self.idle_exit):
                return
            time.sleep(self.poll)

    def _lines(self, fh: BinaryIO) -> Iterator[bytes]:
        """The stream's bytes with every line ending as ``\n`` (CR-only and CRLF files too)."""
        held = b""
        for data in self._more(fh):
            data = held + data
            held = b""
            if data.endswith(b"\r"):  # a CRLF may be split between two reads
                data, held = data[:-1], b"\r"
            if b"\r" in data:
                data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
            if data:
                yield data
        if held:
            yield b"\n"

    def _csv(self, fh: BinaryIO) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        rest = b""
        header: list[str] | None = None
        for data in self._lines(fh):
            rest += data
            cut = rest.rfind(b"\n")
            if cut < 0:
                self._check_line_length(rest)
                continue
            block, rest = rest[: cut + 1], rest[cut + 1 :]
            if header is None:
                # the dialect (semicolons, tabs, a decimal comma) from the first complete lines
                self._dialect = dialect_of_lines(block.decode("utf-8-sig", errors="replace")
                                                 .split("\n", DIALECT_LINES)[:DIALECT_LINES])
                first = block.index(b"\n")
                header = self._header(block[:first])
                block = block[first + 1 :]
                self.line = 1
            if len(block) > MAX_LINE_BYTES:
                # a complete line too long: the rows before it go out first, then the error
                sizes = [len(x) for x in block.split(b"\n")]
                long = next((i for i, n in enumerate(sizes) if n > MAX_LINE_BYTES), None)
                if long is not None:
                    good = b"".join(x + b"\n" for x in block.split(b"\n")[:long])
                    if good:
                        yield from self._parsed(good, header)
                    self._check_line_length(b"x" * sizes[long])
            if block:
                yield from self._parsed(block, header)
            self._check_line_length(rest)
        if rest.strip():
            if header is None:
                self._dialect = dialect_of_lines([rest.decode("utf-8-sig", errors="replace")])
                header = self._header(rest)
            else:
                yield from self._parsed(rest + b"\n", header)
        if header is None:
            raise MeasurementError(f"{self.name}: the stream is empty (expected a header line)")

    def _check_line_length(self, rest: bytes) -> None:
        """A line longer than :data:`MAX_LINE_BYTES` is no measurement row (and is not
        held whole in memory)."""
        if len(rest) > MAX_LINE_BYTES:
            line = self.line + 1
            exc = MeasurementError(f"{self.name}, line {line}: longer than {MAX_LINE_BYTES // 1000} kB: not a row of "
                                   "numbers")
            exc.line = line
            raise exc

    def _parsed(self, block: bytes, header: list[str]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """The rows of a block of lines; at a bad line, the rows before it first, then the error."""
        self._partial = None
        try:
            parsed = self._parse(block, header)
        except MeasurementError:
            if self._partial is not None and self._partial[0].shape[0]:
                yield self._partial
            raise
        yield parsed

    def _header(self, raw: bytes) -> list[str]:
        if len(raw) > MAX_LINE_BYTES:
            raise MeasurementError(f"{self.name}, line 1: the header is longer than {MAX_LINE_BYTES // 1000} kB")
        text = raw.decode("utf-8-sig", errors="replace").strip()
        header = [h.strip() for h in next(csv.reader([text], delimiter=self._dialect.delimiter))] if text else []
        check_header(self.name, header, required=self.required, missing_hint=self.missing_hint)
        self._header_names = header
        return header

    def _parse(self, block: bytes, header: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """``(data in file columns, file line of each row)`` of complete lines; errors name the line."""
        import pyarrow as pa
        from pyarrow import csv as pacsv

        first_line = self.line + 1
        n_lines = block.count(b"\n")
        numeric = self._numeric(header)
        try:
            table = pacsv.read_csv(
                pa.BufferReader(block),
                read_options=pacsv.ReadOptions(column_names=header, use_threads=False),
                parse_options=pacsv.ParseOptions(delimiter=self._dialect.delimiter, newlines_in_values=False),
                convert_options=pacsv.ConvertOptions(column_types={h: pa.float64() for h in header if h in numeric},
                                                     decimal_point=self._dialect.decimal),
            )
            cols = []
            for i, h in enumerate(header):
                c = table.column(i)
                if h in numeric or pa.types.is_floating(c.type) or pa.types.is_integer(c.type):
                    cols.append(np.asarray(c.to_numpy(zero_copy_only=False), dtype=float))
                else:  # a column the stream does not read (a timestamp, a note): nothing
                    cols.append(np.full(len(c), np.nan))
            data = np.column_stack(cols)
            if data.shape[0] == n_lines:
                lines = np.arange(first_line, first_line + n_lines, dtype=np.int64)
            else:  # blank lines were skipped: number the rows from the text
                lines = np.array([first_line + i for i, ln in enumerate(block.split(b"\n")[:-1]) if ln.strip()],
                                 dtype=np.int64)
        except (pa.ArrowInvalid, ValueError):
            data, lines = self._parse_slowly(block, header, first_line)
        self.line += n_lines
        return np.asarray(data, dtype=float).reshape(-1, len(header)), lines

    def _numeric(self, header: list[str]) -> set[str]:
        """The columns that must hold numbers: the required ones and every model column (a
        rate given is read); any other (a timestamp, a note) is read as nothing."""
        return set(self.required) | (set(header) & set(COLUMNS))

    def _parse_slowly(self, block: bytes, header: list[str], first_line: int):
        numeric = self._numeric(header)
        rows, lines = [], []
        text = block.decode("utf-8", errors="replace").split("\n")[:-1]
        for i, raw in enumerate(text):
            line_no = first_line + i
            if not raw.strip():
                continue
            try:
                cells = next(csv.reader([raw], delimiter=self._dialect.delimiter))
            except csv.Error as err:
                self._partial = (np.array(rows, dtype=float).reshape(-1, len(header)), np.array(lines, dtype=np.int64))
                exc = MeasurementError(f"{self.name}, line {line_no}: not a CSV row ({err})")
                exc.line = self.error_line = line_no
                raise exc from None
            if len(cells) != len(header):
                self._partial = (np.array(rows, dtype=float).reshape(-1, len(header)), np.array(lines, dtype=np.int64))
                exc = MeasurementError(f"{self.name}, line {line_no}: {len(cells)} fields, but the header has "
                                       f"{len(header)}")
                exc.line = self.error_line = line_no
                raise exc
            vals = []
            for name, cell in zip(header, cells, strict=True):
                try:
                    vals.append(self._dialect.number(cell))
                except ValueError:
                    if name not in numeric:
                        vals.append(math.nan)
                        continue
                    self._partial = (np.array(rows, dtype=float).reshape(-1, len(header)),
                                     np.array(lines, dtype=np.int64))
                    shown = cell.strip()
                    shown = shown if len(shown) <= 40 else shown[:40] + "..."
                    exc = MeasurementError(f"{self.name}, line {line_no}, column {name!r}: {shown!r} is "
                                           "not a number")
                    exc.line = self.error_line = line_no
                    raise exc from None
            rows.append(vals)
            lines.append(line_no)
        return np.array(rows, dtype=float).reshape(-1, len(header)), np.array(lines, dtype=np.int64)

    def _parquet(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        import pyarrow.parquet as pq

        try:
            pf = pq.ParquetFile(self._path)
        except Exception as exc:
            raise MeasurementError(f"{self._path}: not a readable Parquet file ({exc})") from None
        header = self._header(",".join(pf.schema_arrow.names).encode())
        row = 2
        for batch in pf.iter_batches(batch_size=65536):
            try:
                data = np.column_stack([np.asarray(batch.column(i).to_numpy(zero_copy_only=False), dtype=float)
                                        for i in range(batch.num_columns)])
            except (TypeError, ValueError):
                raise MeasurementError(f"{self._path}: a column is not numeric") from None
            lines = np.arange(row, row + data.shape[0], dtype=np.int64)
            row += data.shape[0]
            yield data, lines
        del header

    # ------------------------------------------------------------------ validation
    def _emit(self, parsed) -> Iterator[np.ndarray]:
        """Validate rows (file columns) and hand them out as the ten model columns."""
        if parsed is None:  # end of stream: the held-back derivatives
            if self._deriv is not None:
                out = self._deriv.finish()
                if out.shape[0]:
                    yield out
            return
        data, lines = parsed
        try:
            out = self._validate(data, lines)
        except MeasurementError as exc:
            # the rows before the bad one are good: they go out first (an alarm they raise is kept)
            row = getattr(exc, "row", 0)
            if row:
                yield from self._emit((data[:row], lines[:row]))
            self.error_line = exc.line = int(lines[row]) if row < len(lines) else None
            raise
        if out is None:
            return
        if self._deriv is not None:
            out = self._deriv.push(out)
        if out.shape[0]:
            self.line = int(lines[-1])
            yield out

    def _validate(self, data: np.ndarray, lines: np.ndarray) -> np.ndarray | None:
        """The rows as the ten model columns; a bad row raises with its index as ``row``
        (the checks are the batch reader's: :func:`~rotor_env.measurements.files.check_finite` ...)."""
        header = self._header_names
        if data.shape[0] == 0:
            return None
        idx = {h: i for i, h in enumerate(header)}
        present = [c for c in COLUMNS if c in idx]
        check_finite(self.name, data[:, [idx[c] for c in present]], present, lines)
        t = data[:, idx["t"]]
        self._dt = self._dt or first_step(t, self._last_t)
        check_time(self.name, t, lines, step=self._dt or None, previous=self._last_t)
        check_tilt(self.name, data[:, [idx["theta_x"], idx["theta_y"]]], ("theta_x", "theta_y"), lines)
        out = np.zeros((data.shape[0], len(COLUMNS)))
        for j, c in enumerate(COLUMNS):
            if c in idx:
                out[:, j] = data[:, idx[c]]
        out[:, 1] = self._phi.push(out[:, 1], lines)
        self._last_t = float(t[-1])
        if self._deriv is None and any(c not in idx for c in DERIVABLE):
            self._deriv = SlidingDerivatives([c for c in DERIVABLE if c not in idx], self._dt)
        return out


class SlidingDerivatives:
    """Savitzky-Golay rates and accelerations on a sliding buffer (as :func:`rotor_env.measurements.files.derive_rates`)."""

    def __init__(self, names: list[str], dt: float) -> None:
        self.targets = [(COLUMNS.index(c), COLUMNS.index(DERIVABLE[c][0]), DERIVABLE[c][1]) for c in names]
        n = max(7, round(0.2 / dt))
        self.window = n + 1 - n % 2
        self.half = self.window // 2
        self.dt = dt
        self.buf = np.zeros((0, len(COLUMNS)))
        self.started = False

    def _filter(self, buf: np.ndarray) -> np.ndarray:
        out = buf.copy()
        poly = min(5, self.window - 1)
        for dst, src, order in self.targets:
            out[:, dst] = savgol_filter(buf[:, src], self.window, poly, deriv=order, delta=self.dt, mode="interp")
        return out

    def push(self, rows: np.ndarray) -> np.ndarray:
        buf = np.concatenate([self.buf, rows])
        if buf.shape[0] < 2 * self.window:
            self.buf = buf
            return np.zeros((0, len(COLUMNS)))
        full = self._filter(buf)
        # hand out the samples whose whole window is in the buffer (the first ones too,
        # at the start: fitted on the first window like the batch filter)
        lo = 0 if not self.started else self.half + 1
        hi = buf.shape[0] - self.half
        self.started = True
        # keep a whole window before the first sample not handed out (its own window's
        # start, and the end fit's window if the stream ends here)
        self.buf = buf[hi - self.half - 1 :]
        return full[lo:hi]

    def finish(self) -> np.ndarray:
        buf = self.buf
        if buf.shape[0] == 0:
            return buf
        if buf.shape[0] < self.window:
            raise MeasurementError(f"too few samples ({buf.shape[0]}) to estimate the rates (a window of "
                                   f"{self.window})")
        full = self._filter(buf)
        self.buf = np.zeros((0, len(COLUMNS)))
        return full[(self.half + 1 if self.started else 0):]


def iter_chunks(source, **kwargs) -> Iterator[np.ndarray]:
    """Shorthand: ``iter(StreamReader(source, **kwargs))``."""
    return iter(StreamReader(source, **kwargs))



_END = object()


def read_ahead(chunks: Iterable, depth: int = 2) -> Iterator:
    """The items of ``chunks``, read up to ``depth`` ahead in a background thread.

    Parsing (pyarrow releases the GIL) then overlaps with the caller's work on the
    previous chunk (the monitor's compiled loop releases it too), so a stream costs the
    slower of the two per sample rather than their sum.  Order is kept; an exception of
    the reader reaches the caller where it happened, after every item before it.  The
    thread is a daemon: a reader left waiting on a followed file never holds up the exit.
    """
    slots: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
    stop = threading.Event()

    def pump() -> None:
        try:
            for item in chunks:
                while not stop.is_set():
                    try:
                        slots.put((item, None), timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            slots.put((_END, None))
        except BaseException as exc:  # handed to the caller, in order
            slots.put((_END, exc))

    worker = threading.Thread(target=pump, name="rotor-id-reader", daemon=True)
    worker.start()
    try:
        while True:
            item, exc = slots.get()
            if exc is not None:
                raise exc
            if item is _END:
                return
            yield item
    finally:
        stop.set()
