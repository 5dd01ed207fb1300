#!/usr/bin/env bash
# Set up .venv, then lint and run the whole test suite. Fails if no test ran (pytest exit 5).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# The report's browser test (tests/test_report_browser.py) needs headless Chromium: install
# the system package when it is absent and we may (root, apt). Without it the test skips,
# except in CI (CI=true), where it fails.
if ! command -v chromium >/dev/null && [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
  echo "run-tests.sh: installing the system package chromium (apt-get) for the report's browser test" >&2
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
    || echo "run-tests.sh: warning: could not install chromium; the browser test will skip (fail in CI)" >&2
fi
.venv/bin/python -m ruff check .
.venv/bin/python -m pytest -n 2 "$@"
