#!/usr/bin/env bash
# Create .venv in the repository root and install rotor-id into it (idempotent).
# The install is editable: a change of the code needs no reinstall, only a change of
# pyproject.toml (dependencies, entry points, package data) does. A stamp holding the hash of
# pyproject.toml and of the Python used skips the install (and pip's output) when neither changed.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
STAMP=.venv/.rotor-id-install-stamp
WANT="$(cat pyproject.toml <(.venv/bin/python -c 'import sys; print(sys.version)') | sha256sum | cut -d' ' -f1)"
if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$WANT" ]; then
  exit 0  # installed from this very pyproject.toml: nothing to do
fi
echo "setup.sh: installing rotor-id and its dependencies into .venv (pyproject.toml changed or first run)" >&2
PIP=(.venv/bin/python -m pip install --quiet --disable-pip-version-check)
"${PIP[@]}" --upgrade pip
# The CPU build of PyTorch first (Stable-Baselines3 needs it); unpinned, pip would pull CUDA.
.venv/bin/python -c "import torch" 2>/dev/null || "${PIP[@]}" torch==2.13.0
"${PIP[@]}" -e '.[dev,agents,fleet,rllib]'
echo "$WANT" > "$STAMP"
