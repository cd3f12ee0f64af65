#!/usr/bin/env bash
# Set up .venv and run the whole test suite (what .ci/run calls). Extra args go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/python -m pytest -q -rs "$@"
