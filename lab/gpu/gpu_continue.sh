#!/usr/bin/env bash
# A large-batch continuation of the shipped weights on a lent GPU, inside one call (docs/model.md,
# "The twelfth session"): renders the training inputs there (the 2.4 GB component cache cannot
# travel), then trains the given configs side by side on the one GPU until the budget is spent,
# and leaves each run's moving-average weights (float16), history and log in OUTDIR.
# Usage: bash bench/gpu_continue.sh OUTDIR BUDGET_SECONDS [DEVICE] [CONFIG ...]
#   (DEVICE cpu with a small budget rehearses it here; WORK=DIR keeps the runs, default out/gpu12)
set -uo pipefail
OUT=${1:?usage: bench/gpu_continue.sh OUTDIR BUDGET_SECONDS [cuda|cpu] [CONFIG ...]}
BUDGET=${2:?budget in seconds}
DEV=${3:-cuda}
shift 3 2>/dev/null || shift $#
CONFIGS=("$@")
[ ${#CONFIGS[@]} -gt 0 ] || CONFIGS=(configs/gpu_continue_s12.json configs/gpu_continue_s12_seed1.json)
PY=${PYTHON:-python3}
WORK=${WORK:-out/gpu12}
T0=$(date +%s)
export PYTHONUNBUFFERED=1
mkdir -p "$OUT" "$WORK"
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1 | tee "$OUT/machine.txt"
$PY -c "import sys, os, torch, numpy; print('python', sys.version.split()[0], 'torch', torch.__version__, 'numpy', numpy.__version__, 'cuda', torch.cuda.is_available(), 'cpus', os.cpu_count())" 2>&1 | tee -a "$OUT/machine.txt"

# 1. The inputs every config needs (they share the corpus and mix): one pool of render workers,
#    one BLAS thread each; one throwaway CPU step makes the train command render them.
OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
  $PY -m specgen_addon train --config "${CONFIGS[0]}" --out "$WORK/prerender" --device cpu --steps 1 --quiet \
  2>&1 | tail -2 | tee "$OUT/prerender.log"
echo "inputs ready after $(( $(date +%s) - T0 )) s" | tee -a "$OUT/machine.txt"

# 2. The runs, side by side, until the budget less a margin for start-up, validation and saving.
LEFT=$(( BUDGET - ($(date +%s) - T0) - 100 ))
MIN=$($PY -c "print(f'{max(0.2, $LEFT / 60):.2f}')")
echo "training for $MIN min per run" | tee -a "$OUT/machine.txt"
i=0
for c in "${CONFIGS[@]}"; do
  OMP_NUM_THREADS=2 $PY -m specgen_addon train --config "$c" --out "$WORK/run$i" --device "$DEV" --max-minutes "$MIN" --quiet \
    > "$WORK/run$i.log" 2>&1 &
  i=$((i + 1))
done
wait
echo "runs done after $(( $(date +%s) - T0 )) s" | tee -a "$OUT/machine.txt"

# 3. What comes back: float16 weights (≤ 16 MB a file), the history and the log's end.
for ((j = 0; j < i; j++)); do
  tail -3 "$WORK/run$j.log" | tee -a "$OUT/machine.txt"
  $PY -m specgen_addon average-weights "$WORK/run$j/specgen.pt" "$WORK/run$j/specgen.pt" -o "$OUT/run$j.pt" --half --overwrite 2>&1 | tail -1
  cp "$WORK/run$j/history.csv" "$OUT/history_run$j.csv" 2>/dev/null
done
ls -la "$OUT"
