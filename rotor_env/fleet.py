"""Fleet diagnosis on Ray: ``rotor-id batch`` diagnoses many recordings at once.

Every recording (a file of a folder or a glob, or one recording of a Parquet dataset
with a recording id column) is diagnosed exactly as ``rotor-id diagnose`` would
(:func:`rotor_env.batch.diagnose_file`), as one task of a Ray Data ``map`` over the
recordings: Ray's local mode on this machine by default (``ray.init(num_cpus=N)``),
or an existing cluster (``--address``).  Results stream back to the driver, which

* writes ``RESULTS/recordings/<id>.json`` as each recording finishes (the checkpoint:
  re-running skips the recordings that have one; ``--retry-errors`` re-runs failed ones),
* writes ``RESULTS/results.parquet`` (a row per recording: verdict, missing effects,
  onsets, coefficients with standard errors, RMS before/after, fit %, critical speeds
  when known, error text) and the fleet summary (``summary.json``, ``summary.png``),
* with ``--reports``, ``RESULTS/reports/<id>.html`` (rendered on the worker, written here).

A recording that cannot be read or diagnosed gets an error row; the batch goes on.
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import json
import math
import os
import re
import sys
import tempfile
import time
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path

from .batch import argparse_type, inertia_ratio, table_amplitude_unit
from .outputs import atomic_write
from .ray_cluster import init_ray, stop_ray

__all__ = [
    "Recording",
    "add_batch_parser",
    "diagnose_recording",
    "find_recordings",
    "results_table",
    "run_batch",
    "summarize",
]

SUFFIXES = (".csv", ".parquet")
DEFAULT_ID_COLUMN = "recording_id"


@dataclass(frozen=True)
class Recording:
    """One recording: a file, or the rows of ``column == value`` of a Parquet dataset."""

    id: str
    path: str
    column: str = ""
    value: str = ""  # JSON of the id value (its type kept: 7 and "7" differ)

    @property
    def key(self) -> str:
        """What a checkpoint is matched on: the real path (``./a`` and ``a`` are one file)
        and, for a file of its own, its size and time stamp (a file replaced is new)."""
        stamp = ""
        if not self.column:
            with contextlib.suppress(OSError):
                st = os.stat(self.path)
                stamp = f"{st.st_size}:{st.st_mtime_ns}"
        return f"{os.path.realpath(self.path)}|{self.column}|{self.value}|{stamp}"

    @property
    def source(self) -> str:
        return f"{self.path}[{self.column}={json.loads(self.value)!r}]" if self.column else self.path


# ---------------------------------------------------------------------- finding the recordings
def _dataset_ids(path: Path, column: str) -> list | None:
    """The id values of a Parquet dataset holding ``column``; None if it is not one."""
    import pyarrow.dataset as pds

    try:
        ds = pds.dataset(str(path), format="parquet")
    except Exception:
        return None
    if column not in ds.schema.names:
        return None
    values = ds.to_table(columns=[column])[column].unique().to_pylist()
    return sorted((v for v in values if v is not None), key=lambda v: (str(type(v)), v))


def _in_output_folder(path: Path, exclude: list[Path], root: Path | str) -> bool:
    """``path`` lies in an excluded folder, or in a folder rotor-id wrote (its marker) below
    the input ``root``: results of a batch are never taken for recordings by the next one."""
    from .outputs import MARKER

    real = Path(os.path.realpath(path))
    top = Path(os.path.realpath(root))
    return any(p in exclude or (top in p.parents and (p / MARKER).is_file()) for p in real.parents)


def find_recordings(inputs: list[str], id_column: str = DEFAULT_ID_COLUMN,
                    exclude: list[Path] | None = None) -> list[Recording]:
    """The recordings named by ``inputs``: files, folders (their ``.csv``/``.parquet``
    files, recursively), globs, or Parquet datasets (a file or a folder) with ``id_column``.
    Files inside a folder rotor-id wrote (or one of ``exclude``) are left out of folders and globs.
    Raises ``ValueError`` for an input that names nothing and for two recordings of one id."""
    exclude = [Path(os.path.realpath(p)) for p in exclude or []]
    out: list[Recording] = []
    for item in inputs:
        path = Path(item)
        if not path.exists() and any(ch in item for ch in "*?["):
            matches = sorted(glob.glob(item, recursive=True))
            prefix = re.split(r"[*?\[]", item)[0]  # the folder the pattern starts in
            top = Path(prefix or ".") if prefix.endswith(("/", os.sep)) or not prefix else Path(prefix).parent
            files = [Path(m) for m in matches if Path(m).is_file() and not _in_output_folder(Path(m), exclude, top)]
            if not files:
                raise ValueError(f"{item}: the pattern matches no file")
            out.extend(_file_recordings(files, None, id_column))
        elif path.is_dir():
            ids = _dataset_ids(path, id_column) if any(path.rglob("*.parquet")) and not any(
                path.rglob("*.csv")) else None
            if ids is not None:
                out.extend(Recording(str(v), str(path), id_column, json.dumps(v)) for v in ids)
                continue
            files = sorted(p for p in path.rglob("*") if p.is_file() and p.suffix.lower() in SUFFIXES
                           and not _in_output_folder(p, exclude, path))
            if not files:
                raise ValueError(f"{item}: the folder holds no .csv or .parquet file")
            out.extend(_file_recordings(files, path, id_column))
        elif path.is_file():
            out.extend(_file_recordings([path], None, id_column))
        else:
            raise ValueError(f"{item}: no such file, folder or pattern")
    seen: dict[str, str] = {}
    for r in out:
        if r.id in seen and seen[r.id] != r.source:
            raise ValueError(f"two recordings have the id {r.id!r}: {seen[r.id]} and {r.source}; "
                             "name them apart (folders give ids relative to the folder)")
        seen[r.id] = r.source
    unique = {r.source: r for r in out}  # one input named twice: diagnosed once
    return list(unique.values())


def _file_recordings(files: list[Path], root: Path | None, id_column: str) -> list[Recording]:
    out = []
    for f in files:
        if f.suffix.lower() == ".parquet":
            ids = _dataset_ids(f, id_column)
            if ids is not None:
                out.extend(Recording(str(v), str(f), id_column, json.dumps(v)) for v in ids)
                continue
        rid = str(f.relative_to(root).with_suffix("")) if root is not None else f.stem
        out.append(Recording(rid.replace(os.sep, "/"), str(f)))
    return out


def _safe_name(rid: str) -> str:
    """A file name for a recording id (ids may hold '/' and other characters)."""
    name = re.sub(r"[^A-Za-z0-9._=-]+", "_", rid.replace("/", "__")).strip("._") or "recording"
    if name != rid.replace("/", "__") or "__" in rid:  # two ids that clean to one name stay apart
        import hashlib

        name += "-" + hashlib.sha1(rid.encode()).hexdigest()[:8]
    return name


# ---------------------------------------------------------------------- one recording (on a worker)
def _materialise(rec: Recording, folder: str) -> str:
    """The file to diagnose: the recording's own, or its rows of the dataset as Parquet."""
    if not rec.column:
        return rec.path
    import pyarrow.dataset as pds
    import pyarrow.parquet as pq

    ds = pds.dataset(rec.path, format="parquet")
    table = ds.to_table(filter=pds.field(rec.column) == json.loads(rec.value))
    table = table.drop_columns([rec.column])
    path = os.path.join(folder, _safe_name(rec.id) + ".parquet")
    pq.write_table(table, path)
    return path


def diagnose_recording(rec: Recording | dict, options: dict) -> dict:
    """Diagnose one recording; never raises (an error becomes the row's ``error``).

    Returns ``{"recording", "source", "ok", "result_json", "error", "seconds", "report"}``:
    the diagnosis as JSON text, and the HTML report (bytes) when ``options["reports"]``.
    """
    from .batch import diagnose_file

    if isinstance(rec, dict):
        rec = Recording(**{k: rec[k] for k in ("id", "path", "column", "value")})
    t0 = time.perf_counter()
    row = {"recording": rec.id, "source": rec.source, "key": rec.key, "ok": False, "result_json": "", "error": "",
           "seconds": 0.0, "report": b""}
    try:
        with tempfile.TemporaryDirectory(prefix="rotor-id-batch-") as tmp:
            path = _materialise(rec, tmp)
            result = diagnose_file(path, model=options.get("model"), ip=options.get("ip"),
                                   alpha=options.get("alpha", 0.05), slow_roll=options.get("slow_roll"),
                                   vectors=bool(options.get("vectors")), rig=options.get("rig"),
                                   amp_unit=options.get("amp_unit", "um"), phase=options.get("phase", "lag"))
            data = json.loads(result.to_json())
            if rec.column:
                data["source"] = rec.source
            row["result_json"] = json.dumps(data)
            if options.get("reports"):
                report = os.path.join(tmp, "report.html")
                result.report(report, overwrite=True)
                row["report"] = Path(report).read_bytes()
            row["ok"] = True
    except Exception as exc:  # the batch goes on: the row says what went wrong
        message = str(exc) or type(exc).__name__
        row["error"] = message if type(exc).__name__ in message else f"{type(exc).__name__}: {message}"
    row["seconds"] = time.perf_counter() - t0
    return row


# ---------------------------------------------------------------------- the results table
def _finite(v):
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def _flat(values: dict, prefix: str = ""):
    """``(name, number)`` pairs; nested ``{effect: {parameter: value}}`` (1X tables) as
    ``effect.parameter``."""
    for k, v in values.items():
        if isinstance(v, dict):
            yield from _flat(v, f"{prefix}{k}.")
        elif not isinstance(v, list):
            yield f"{prefix}{k}", v


def flat_row(record: dict) -> dict:
    """One row of ``results.parquet`` from a recording's JSON (see :func:`_record`)."""
    d = record.get("diagnosis") or {}
    ses = d.get("standard_errors") or {}
    coefs = d.get("coefficients") or d.get("physical") or {}
    onset = d.get("onset") or {}
    return {
        "recording": record["recording"],
        "source": record["source"],
        "status": record["status"],
        "kind": d.get("kind", "dimensionless") if d else None,
        "verdict": d.get("verdict"),
        "missing": [str(m) for m in d.get("missing") or []],
        "onsets": [{"effect": str(k), "t": _finite(v)} for k, v in onset.items()],
        "coefficients": [{"name": name, "value": _finite(v), "standard_error": _finite(ses.get(name))}
                         for name, v in _flat(coefs)],
        "rms_before": _finite(d.get("rms_before")),
        "rms_after": _finite(d.get("rms_after")),
        "noise_floor": _finite(d.get("noise_floor")),
        "fit_percent_before": _finite(d.get("fit_percent_before")),
        "fit_percent_after": _finite(d.get("fit_percent_after")),
        "criticals": [{"rpm": _finite(c.get("rpm")), "damping_ratio": _finite(c.get("damping_ratio"))}
                      for c in d.get("criticals") or []],
        "ip": _finite(d.get("ip")),
        "error": record.get("error") or None,
        "seconds": _finite(record.get("seconds")),
    }


def _schema():
    import pyarrow as pa

    f64, s = pa.float64(), pa.string()
    return pa.schema([
        ("recording", s), ("source", s), ("status", s), ("kind", s), ("verdict", s),
        ("missing", pa.list_(s)),
        ("onsets", pa.list_(pa.struct([("effect", s), ("t", f64)]))),
        ("coefficients", pa.list_(pa.struct([("name", s), ("value", f64), ("standard_error", f64)]))),
        ("rms_before", f64), ("rms_after", f64), ("noise_floor", f64),
        ("fit_percent_before", f64), ("fit_percent_after", f64),
        ("criticals", pa.list_(pa.struct([("rpm", f64), ("damping_ratio", f64)]))),
        ("ip", f64), ("error", s), ("seconds", f64),
    ])


def results_table(records: list[dict]):
    """The Parquet table (a ``pyarrow.Table``) of the recordings' JSON records."""
    import pyarrow as pa

    return pa.Table.from_pylist([flat_row(r) for r in records], schema=_schema())


def summarize(records: list[dict]) -> dict:
    """Counts per verdict (errors as ``error``) and per missing effect."""
    verdicts = Counter((r.get("diagnosis") or {}).get("verdict") if r["status"] == "ok" else "error"
                       for r in records)
    missing = Counter(m for r in records for m in ((r.get("diagnosis") or {}).get("missing") or []))
    return {"recordings": len(records), "ok": sum(r["status"] == "ok" for r in records),
            "errors": sum(r["status"] != "ok" for r in records),
            "verdicts": dict(verdicts.most_common()), "missing": dict(missing.most_common())}


def summary_figure(summary: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    for ax, key, title in ((axes[0], "verdicts", "verdict"), (axes[1], "missing", "missing effect")):
        items = list(summary[key].items())[::-1]
        names = [str(k) for k, _ in items] or ["(none)"]
        counts = [v for _, v in items] or [0]
        ax.barh(names, counts, color="#4477aa" if key == "verdicts" else "#cc6677")
        ax.set_title(f"recordings per {title} (of {summary['recordings']})")
        ax.set_xlabel("recordings")
        for y, c in enumerate(counts):
            ax.text(c, y, f" {c}", va="center")
    fig.savefig(path, dpi=110, format="png")  # the path may be a temporary name without .png
    plt.close(fig)


def format_summary(summary: dict) -> str:
    lines = [f"{summary['recordings']} recordings: {summary['ok']} diagnosed, {summary['errors']} errors",
             "", "| verdict | recordings |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in summary["verdicts"].items()]
    lines += ["", "| missing effect | recordings |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in summary["missing"].items()] or ["| (none) | 0 |"]
    return "\n".join(lines)


# ---------------------------------------------------------------------- the batch
def _atomic_write(path: Path, data: bytes) -> None:
    # a re-run replaces what an earlier run of the batch wrote there
    atomic_write(path, lambda tmp: tmp.write_bytes(data), overwrite=True)


def _record(row: dict) -> dict:
    return {"recording": row["recording"], "source": row["source"], "key": row["key"],
            "status": "ok" if row["ok"] else "error",
            "error": row["error"] or None, "seconds": row["seconds"],
            "diagnosis": json.loads(row["result_json"]) if row["ok"] else None}


def run_batch(inputs: list[str], out: str | Path, *, workers: int = 1, address: str | None = None,
              options: dict | None = None, id_column: str = DEFAULT_ID_COLUMN, retry_errors: bool = False,
              progress: bool | None = None, log=None) -> dict:
    """Diagnose every recording of ``inputs`` on Ray; write the results under ``out``.

    Returns ``{"summary", "table", "done", "skipped", "seconds"}`` (``table``: the path of
    ``results.parquet``).  ``options``: :func:`diagnose_recording`'s (model, ip, alpha,
    slow_roll, vectors, rig, amp_unit, phase, reports).
    """
    if workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    options = dict(options or {})
    if options.get("rig"):
        options["rig"] = str(Path(options["rig"]).resolve())
    if options.get("model") is not None:
        from .batch import model_list

        model_list(options["model"], ())  # refuses a bad effect name before any work
    out = Path(out)
    from .outputs import OutputFolder

    # a new or empty folder, or one a previous batch wrote (its marker: the run resumes);
    # a folder holding anything else is refused before any work — its files are never replaced
    OutputFolder.check(out, resume=True)
    recordings = find_recordings(inputs, id_column, exclude=[out])
    folder = OutputFolder(out, resume=True)
    rec_dir = out / "recordings"
    rec_dir.mkdir(exist_ok=True)
    if options.get("reports"):
        (out / "reports").mkdir(exist_ok=True)
    say = log or (lambda msg: print(msg, file=sys.stderr, flush=True))

    def done_record(rec: Recording) -> dict | None:
        path = rec_dir / f"{_safe_name(rec.id)}.json"
        if not path.exists():
            return None
        try:
            record = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            return None  # a torn checkpoint: diagnose again
        if record.get("key") != rec.key or (retry_errors and record.get("status") != "ok"):
            return None
        return record

    previous = {r.id: done_record(r) for r in recordings}
    todo = [r for r in recordings if previous[r.id] is None]
    skipped = len(recordings) - len(todo)
    if skipped:
        say(f"rotor-id batch: {skipped} of {len(recordings)} recordings already done in {out} (skipped)")
    t0 = time.perf_counter()
    records = {k: v for k, v in previous.items() if v is not None}
    # every file the run may write, in the marker before it is written (one marker write)
    folder.register([f"recordings/{_safe_name(r.id)}.json" for r in todo]
                    + ([f"reports/{_safe_name(r.id)}.html" for r in todo] if options.get("reports") else [])
                    + ["results.parquet", "summary.json", "summary.png"])
    if todo:
        records.update(_run_on_ray(todo, options, workers, address, out, rec_dir, progress, say))
    ordered = [records[r.id] for r in recordings if r.id in records]
    import pyarrow.parquet as pq

    table_path = folder.write("results.parquet", lambda p: pq.write_table(results_table(ordered), p))
    summary = summarize(ordered)
    folder.write_bytes("summary.json", json.dumps(summary, indent=2).encode())
    folder.write("summary.png", lambda p: summary_figure(summary, p))
    return {"summary": summary, "table": str(table_path), "done": len(todo), "skipped": skipped,
            "seconds": time.perf_counter() - t0}


def _run_on_ray(todo, options, workers, address, out, rec_dir, progress, say) -> dict:
    import logging

    import ray
    import ray.data

    from .progress import step

    step("starting Ray")
    started = init_ray(workers, address)
    logging.getLogger("ray.data").setLevel(logging.ERROR)  # its execution banners: the log lines are ours
    try:
        ctx = ray.data.DataContext.get_current()
        ctx.enable_progress_bars = False  # ours below, also without a terminal
        if hasattr(ctx, "print_on_execution_start"):
            ctx.print_on_execution_start = False
        concurrency = workers if not address else max(1, int(ray.cluster_resources().get("CPU", workers)))
        ds = ray.data.from_items([asdict(r) for r in todo], override_num_blocks=len(todo))
        ds = ds.map(diagnose_recording, fn_kwargs={"options": options}, num_cpus=1,
                    compute=ray.data.TaskPoolStrategy(size=concurrency))
        return _collect(ds.iter_rows(), len(todo), out, rec_dir, bool(options.get("reports")), progress, say)
    finally:
        if started:
            stop_ray()


def _collect(rows, total: int, out: Path, rec_dir: Path, reports: bool, progress, say) -> dict:
    """Write each finished recording's JSON (and report) as it arrives; show progress."""
    from tqdm.auto import tqdm

    tty = sys.stderr.isatty() if progress is None else bool(progress)
    from .progress import active, step

    # under the command the bar and the lines between the rows are rotor_env/progress.py's
    step("diagnosing recordings", total, "recordings")
    bar = tqdm(total=total, desc="diagnosing", unit="recording", disable=not tty or active() is not None)
    records, errors, t0, last = {}, 0, time.perf_counter(), 0.0
    for row in rows:
        record = _record(row)
        name = _safe_name(record["recording"])
        if reports and row.get("report"):
            _atomic_write(out / "reports" / f"{name}.html", bytes(row["report"]))
        _atomic_write(rec_dir / f"{name}.json", json.dumps(record).encode())
        records[record["recording"]] = record
        errors += record["status"] != "ok"
        bar.update(1)
        bar.set_postfix(errors=errors)
        if active() is not None:
            active().advance(1)
        now = time.perf_counter() - t0
        if not tty and (now - last >= 10 or len(records) == total):  # log lines without a terminal
            last = now
            say(f"rotor-id batch: {len(records)}/{total} recordings ({errors} errors), {now:.0f} s")
    bar.close()
    return records


# ---------------------------------------------------------------------- the command
def _cmd_batch(args: argparse.Namespace) -> int:
    try:
        import ray  # noqa: F401
    except ImportError as exc:
        print(f"rotor-id batch: needs Ray (pip install 'rotor-id[fleet]'): {exc}", file=sys.stderr)
        return 2
    options = {"model": args.model, "ip": args.ip, "alpha": args.alpha, "slow_roll": args.slow_roll,
               "vectors": args.vectors, "rig": args.rig, "amp_unit": args.amp_unit, "phase": args.phase,
               "reports": args.reports}
    result = run_batch(args.inputs, args.out, workers=args.workers, address=args.address, options=options,
                       id_column=args.id_column, retry_errors=args.retry_errors,
                       progress=None if not args.json else False)
    if args.json:
        print(json.dumps({"summary": result["summary"], "table": result["table"], "done": result["done"],
                          "skipped": result["skipped"]}))
    else:
        print(format_summary(result["summary"]))
        print(f"\nresults: {result['table']} ({result['done']} diagnosed now, {result['skipped']} skipped as "
              f"done, {result['seconds']:.1f} s); per recording: {Path(args.out) / 'recordings'}/; "
              f"summary: {Path(args.out) / 'summary.json'}, {Path(args.out) / 'summary.png'}")
    return 1 if result["summary"]["errors"] and not result["summary"]["ok"] else 0



def add_batch_parser(sub) -> None:
    p = sub.add_parser(
        "batch", help="diagnose a fleet of recordings on Ray (local, or a cluster with --address)",
        description="Diagnose every recording of INPUT... (files, folders, globs, or Parquet datasets with a "
        "recording id column) as 'rotor-id diagnose' would, in parallel on Ray, and write RESULTS/results.parquet "
        "(a row per recording), RESULTS/recordings/<id>.json and the fleet summary. Re-running skips recordings "
        "already done; a recording that fails gets an error row and the batch goes on.")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="a file, a folder, a glob ('runs/**/*.csv'), or a "
                   "Parquet dataset with the --id-column")
    p.add_argument("--out", required=True, metavar="RESULTS", help="results folder (created; reused to resume)")
    p.add_argument("--workers", type=int, default=max(1, os.cpu_count() or 1),
                   help="parallel diagnoses in Ray's local mode (default: the CPU count)")
    p.add_argument("--address", metavar="ADDR", help="an existing Ray cluster ('auto', or ray://HOST:10001); "
                   "every node needs rotor-id installed")
    p.add_argument("--model", metavar="A,B,...", help="the model to start from (default: as 'rotor-id diagnose')")
    p.add_argument("--ip", type=argparse_type(inertia_ratio), default=None, help="inertia ratio I_p/I_t (default: estimated)")
    p.add_argument("--alpha", type=float, default=0.05, help="significance level (default 0.05)")
    p.add_argument("--slow-roll", type=float, default=None, metavar="SPEED", help="slow-roll compensation")
    p.add_argument("--vectors", action="store_true", help="the recordings are order-tracked 1X tables")
    p.add_argument("--rig", metavar="RIG.yaml", help="the recordings are this rig's raw waveforms (or, with "
                   "--vectors, its probes' tables)")
    p.add_argument("--amp-unit", default="um", type=argparse_type(table_amplitude_unit),
                   help="--vectors amplitude unit (um, mil, mm, m; 'mil pp' for peak to peak, 'um rms'; default um, "
                        "zero to peak)")
    p.add_argument("--phase", default="lag", choices=("lag", "lead"), help="--vectors phase convention")
    p.add_argument("--id-column", default=DEFAULT_ID_COLUMN, help="the recording id column of a Parquet dataset "
                   f"(default {DEFAULT_ID_COLUMN})")
    p.add_argument("--reports", action="store_true", help="also write RESULTS/reports/<id>.html")
    p.add_argument("--retry-errors", action="store_true", help="diagnose again the recordings that failed")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=_cmd_batch)
