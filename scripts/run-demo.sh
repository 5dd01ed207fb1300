#!/usr/bin/env bash
# Set up .venv, then run the main job.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# compile the rig diagnosis's kernels once per machine (about a minute the first time, seconds
# after): the first rig record a user diagnoses then runs at the speed the README states
.venv/bin/rotor-id warm-up
# --force replaces only the files of a previous demo in its own folder (see rotor_env/outputs.py)
.venv/bin/rotor-id demo --force "$@"
