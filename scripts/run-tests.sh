#!/usr/bin/env bash
# Set up .venv, then lint and run the whole test suite. Fails if no test ran (pytest exit 5).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/python -m ruff check .
.venv/bin/python -m pytest -n 2 "$@"
