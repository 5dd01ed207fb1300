#!/usr/bin/env bash
# Set up .venv, then run the main job.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# --force replaces only the files of a previous demo in its own folder (see rotor_env/outputs.py)
.venv/bin/rotor-id demo --force "$@"
