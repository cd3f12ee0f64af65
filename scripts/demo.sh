#!/usr/bin/env bash
# Set up .venv and run the main job on the shipped defaults (see README).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
out=${1:-out/demo}
exec .venv/bin/python batch.py --image examples/sphere.png --mesh suzanne --env forest --out "$out" --overwrite
