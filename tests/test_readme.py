"""Every README snippet runs (issue 25, item 6).

The Python blocks are extracted and run, each in a fresh process in an empty folder (a
block that starts with ``# NAME.py`` is a module: written there and imported).  The bash
blocks run when the line before them is ``<!-- readme-test: run -->`` (the safe and quick
ones; the others train, run for minutes or need a cluster), with ``set -euo pipefail`` and
the ``rotor-id`` of this interpreter on ``PATH``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RUN_MARK = "<!-- readme-test: run -->"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


def blocks(language: str) -> list[tuple[int, str, bool]]:
    """``(line, code, marked)`` of every fenced block of ``language`` in the README."""
    return [(line, code, marked) for line, lang, code, marked, _ in _fenced() if lang == language]


def _fenced() -> list[tuple[int, str, str, bool, str]]:
    """``(line, language, code, marked, next block's code)`` of every fenced block."""
    text = README.read_text(encoding="utf-8")
    found = list(FENCE.finditer(text))
    out = []
    for i, m in enumerate(found):
        line = text.count("\n", 0, m.start()) + 1
        before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        nxt = found[i + 1] if i + 1 < len(found) else None
        follows = nxt.group(2) if nxt is not None and nxt.group(1) == "json" and \
            text[m.end():nxt.start()].strip() == "" else ""
        out.append((line, m.group(1), m.group(2), before.strip() == RUN_MARK, follows))
    return out


def _env() -> dict[str, str]:
    path = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")])
    return {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg", "PATH": path, "OMP_NUM_THREADS": "1"}


PYTHON = blocks("python")
BASH = [b for b in blocks("bash") if b[2]]
CLAIMS = {line: follows for line, lang, _, marked, follows in _fenced() if lang == "bash" and marked}


def test_the_readme_has_snippets_to_run():
    assert len(PYTHON) >= 4 and len(BASH) >= 1


@pytest.mark.parametrize(("line", "code"), [(ln, c) for ln, c, _ in PYTHON], ids=[f"line{b[0]}" for b in PYTHON])
def test_python_snippet_runs(line, code, tmp_path):
    first = code.splitlines()[0].strip()
    module = re.fullmatch(r"#\s*(\w+)\.py", first)
    if module:  # a module the text then uses (a user effect): written and imported
        (tmp_path / f"{module.group(1)}.py").write_text(code)
        code = f"import {module.group(1)}"
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(), capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, f"README.md line {line}: the snippet fails:\n{proc.stderr[-3000:]}"


@pytest.mark.parametrize(("line", "code"), [(ln, c) for ln, c, _ in BASH], ids=[f"line{b[0]}" for b in BASH])
def test_bash_snippet_runs(line, code, tmp_path):
    proc = subprocess.run(["bash", "-c", "set -euo pipefail\n" + code], cwd=tmp_path, env=_env(),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"README.md line {line}: the snippet fails:\n{proc.stderr[-3000:]}"
    assert proc.stdout.strip(), f"README.md line {line}: the snippet printed nothing"
    # the alarms the JSON block after it shows (effect, alarm time) are what the command prints
    for effect, t_alarm in re.findall(r'"effect": "(\w+)", "t_alarm": ([0-9.]+)', CLAIMS[line]):
        assert f'"effect": "{effect}", "t_alarm": {t_alarm}' in proc.stdout, (
            f"README.md line {line}: claims {effect} at t_alarm {t_alarm}; the command printed:\n{proc.stdout[-2000:]}")


def _rotor_id_commands() -> list[tuple[int, str]]:
    """Every ``rotor-id ...`` command of every bash block (continued lines joined, pipes split,
    redirections and comments dropped).  A command built from shell variables (a loop's
    ``$1``) is a template, not a command line: it is checked with its variables replaced by a
    plausible value of the option they fill (a number, else a file name)."""
    import re

    out = []
    for line, code, _ in blocks("bash"):
        lines = code.splitlines()
        k = 0
        while k < len(lines):
            first = k
            text = lines[k]
            while text.rstrip().endswith("\\") and k + 1 < len(lines):
                k += 1
                text = text.rstrip()[:-1] + " " + lines[k].strip()
            k += 1
            text = text.split(" #")[0].strip()
            for part in text.split("|"):
                part = re.split(r"\s\d?>>?\s", " " + part.strip() + " ")[0].strip()
                if part.startswith("rotor-id "):
                    # $((rpm + 1)) and $rpm stand for numbers; $1_$rpm.csv for a file name
                    part = re.sub(r"\$\(\([^)]*\)\)", "1000", part)
                    part = re.sub(r"\$\w+", "1000", part)
                    out.append((line + 1 + first, part))
    return out


@pytest.mark.parametrize(("line", "command"), _rotor_id_commands(), ids=[f"line{c[0]}" for c in _rotor_id_commands()])
def test_every_readme_command_line_parses(line, command, capsys):
    """Not run (they train, take minutes or need a cluster): each parses with today's options."""
    import shlex

    from rotor_env.cli import build_parser

    try:
        build_parser().parse_args(shlex.split(command)[1:])
    except SystemExit as exc:
        if exc.code:
            pytest.fail(f"README.md line {line}: {command!r} does not parse: {capsys.readouterr().err[-500:]}")


def test_readme_commands_run_in_order_in_one_folder():
    """A newcomer runs the README's blocks in order in one folder: no command may refuse an
    output that an earlier command wrote (``rotor-id`` never overwrites without ``--force``).
    Measured from a fresh clone (docs/README_MEASURED.md): the rig monitor example's
    ``simulate run.csv`` failed on the ``run.csv`` of the block before it, and the monitor then
    read the wrong file."""
    import shlex

    from rotor_env.cli import build_parser

    written: dict[str, int] = {}
    clashes = []
    for line, command in _rotor_id_commands():
        args = build_parser().parse_args(shlex.split(command)[1:])
        outputs = [getattr(args, "out", None) if args.command == "simulate" else None,
                   getattr(args, "report", None), getattr(args, "figures", None)]
        for out in filter(None, outputs):
            if out in written and not getattr(args, "force", False):
                clashes.append(f"README.md line {line}: {command!r} writes {out}, already written at line "
                               f"{written[out]}, without --force")
            written.setdefault(out, line)
    assert not clashes, "\n".join(clashes)
