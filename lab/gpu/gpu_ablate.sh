#!/usr/bin/env bash
# Ablation arms on a lent GPU, inside one call of the lease (docs/ablations.md, "Twenty-eighth
# session"). Installs the carried wheels, renders the inputs, trains every (arm, seed) at once until
# UNTIL seconds after the start, packs the complete arms into one tar and hands back its 15 MiB
# chunks FIRST..LAST (a lease returns at most 8 files of 16 MB, 64 MB in all, so four arms need two
# calls; the tar stays on the held machine in out/gpu_ablate/). A second call with the same seeds
# resumes unfinished arms from their checkpoints, or only hands back the remaining chunks (UNTIL 0).
# Usage: bash bench/gpu_ablate.sh OUTDIR UNTIL FIRST LAST SEED...   (carry .whl and .gpuenv;
#   rehearse here with DEVICE=cpu STEPS=3 EXTRA=--smoke PYTHON=.venv/bin/python)
set -uo pipefail
OUT=${1:?usage: bench/gpu_ablate.sh OUTDIR UNTIL FIRST LAST SEED...}
UNTIL=${2:?seconds}; FIRST=${3:?first chunk}; LAST=${4:?last chunk}
shift 4
SEEDS=("$@")
PY=${PYTHON:-python3}
WORK=out/gpu_ablate
mkdir -p "$OUT" "$WORK"
export PYTHONUNBUFFERED=1 NVIDIA_TF32_OVERRIDE=0 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
if ! $PY -c "import colour, OpenEXR" 2>/dev/null; then  # the lent machine's image lacks the two
  [ -d /tmp/site ] || $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
      --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD/.gpuenv/envs  # and the bpy wheel's studio-light maps (docs/scale.md §2b)
fi
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
$PY -c "import sys, os, torch, numpy; print('python', sys.version.split()[0], 'torch', torch.__version__, 'numpy', numpy.__version__, 'cuda', torch.cuda.is_available(), 'cpus', os.cpu_count())"
ARGS=(--steps ${STEPS:-6000} ${EXTRA:-} --seeds "${SEEDS[@]}" --arms joint-aff joint-hadamard)
if [ "$UNTIL" -gt 0 ]; then
  $PY bench/gpu_ablate.py "${ARGS[@]}" --device "${DEVICE:-cuda}" --data-workers 2 --render-workers 16 --train-until "$UNTIL" \
      2>&1 | grep -v "it/s\]" | tee -a "$WORK/log.txt"
  rm -f "$WORK"/arms.tar "$WORK"/chunk.*
  $PY bench/gpu_ablate.py "${ARGS[@]}" --pack "$WORK/arms.tar" && split -b 15M -d "$WORK/arms.tar" "$WORK/chunk."
fi
ls -la "$WORK"
for ((i = FIRST; i <= LAST; i++)); do
  c=$(printf '%s/chunk.%02d' "$WORK" "$i")
  [ -f "$c" ] && cp "$c" "$OUT/"
done
sha256sum "$WORK/arms.tar" 2>/dev/null
grep -h "gpu_ablate\|step\b" "$WORK/log.txt" | tail -20 > "$OUT/log_tail.txt" 2>/dev/null
exit 0
