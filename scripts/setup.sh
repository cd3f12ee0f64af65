#!/usr/bin/env bash
# Create/refresh .venv (Python 3.11) from requirements.txt. Idempotent: re-installs only when
# requirements.txt changed since the last successful install.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
if ! command -v "$PY" >/dev/null 2>&1; then
  echo "error: $PY not found; SpecGen needs Python 3.11 (the bpy 5.0.1 wheel is built for it)" >&2
  exit 2
fi
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.requirements.sha256
want=$(sha256sum requirements.txt | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  .venv/bin/python -m pip install --quiet --upgrade pip
  .venv/bin/python -m pip install --quiet -r requirements.txt
  echo "$want" > "$stamp"
fi
# The package itself, editable: `specgen` and `python -m specgen_addon` from any folder.
if [ ! -x .venv/bin/specgen ]; then
  .venv/bin/python -m pip install --quiet --no-deps -e .
fi
