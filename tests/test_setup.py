"""Set-up without noise (issue 25, item 7): ``scripts/setup.sh`` installs only when
pyproject.toml changed, the packaging builds without setuptools warnings and ships the
trained policies, and ``run-tests.sh`` says before it apt-installs chromium."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# A stand-in for .venv/bin/python: logs every call; `import torch` succeeds.
FAKE_PYTHON = """#!/usr/bin/env bash
echo "$*" >> "$(dirname "$0")/../calls.log"
if [ "$1" = "-c" ]; then exec python3 "$@"; fi
exit 0
"""


def _fake_checkout(tmp_path: Path) -> Path:
    repo = tmp_path / "repo"
    (repo / "scripts").mkdir(parents=True)
    shutil.copy(ROOT / "scripts" / "setup.sh", repo / "scripts" / "setup.sh")
    shutil.copy(ROOT / "pyproject.toml", repo / "pyproject.toml")
    bin_dir = repo / ".venv" / "bin"
    bin_dir.mkdir(parents=True)
    (bin_dir / "python").write_text(FAKE_PYTHON)
    (bin_dir / "python").chmod(0o755)
    return repo


def _installs(repo: Path) -> list[str]:
    log = repo / ".venv" / "calls.log"
    lines = log.read_text().splitlines() if log.exists() else []
    return [ln for ln in lines if ln.startswith("-m pip install") and "-e" in ln.split()]


@pytest.mark.skipif(shutil.which("bash") is None or shutil.which("sha256sum") is None, reason="needs bash")
def test_setup_installs_once_then_only_when_pyproject_changes(tmp_path):
    repo = _fake_checkout(tmp_path)
    run = lambda: subprocess.run(["bash", "scripts/setup.sh"], cwd=repo, capture_output=True, text=True,  # noqa: E731
                                 check=True, timeout=60)
    first = run()
    assert len(_installs(repo)) == 1
    assert "installing rotor-id" in first.stderr
    second = run()
    assert len(_installs(repo)) == 1, "nothing changed: no second pip install -e"
    assert second.stdout == second.stderr == ""
    with open(repo / "pyproject.toml", "a") as fh:
        fh.write("\n# a new dependency\n")
    run()
    assert len(_installs(repo)) == 2, "pyproject.toml changed: installed again"


def test_run_tests_says_it_installs_chromium():
    text = (ROOT / "scripts" / "run-tests.sh").read_text()
    i_say = text.find("installing the system package chromium")
    i_apt = text.find("apt-get install")
    assert 0 <= i_say < i_apt, "run-tests.sh must say it installs chromium before apt-get does it"


def test_wheel_builds_without_setuptools_warnings_and_ships_the_policies(tmp_path):
    pytest.importorskip("setuptools")
    src = tmp_path / "src"
    # a copy without build leftovers, so that nothing is written into the checkout
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "out", "build", "*.egg-info",
                                                             "__pycache__", ".pytest_cache", ".ruff_cache"))
    env = {**os.environ, "PYTHONWARNINGS": "always"}
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                           "--disable-pip-version-check", "-v", "-w", str(tmp_path / "dist"), str(src)],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    log = proc.stdout + proc.stderr
    assert "deprecated" not in log, [ln for ln in log.splitlines() if "deprecated" in ln]
    assert "would be ignored" not in log, [ln for ln in log.splitlines() if "ignored" in ln]
    (wheel,) = (tmp_path / "dist").glob("rotor_id-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for policy in (ROOT / "agents" / "policies").iterdir():
        for f in policy.rglob("*"):
            if f.is_file():
                assert f.relative_to(ROOT).as_posix() in names, f"{f} missing from the wheel"
    assert "agents/hyperparams.yml" in names and "rotor_env/cli.py" in names
