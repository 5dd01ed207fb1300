#!/usr/bin/env bash
# Set up .venv, then run the main job.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/rotor-id demo --force "$@"
