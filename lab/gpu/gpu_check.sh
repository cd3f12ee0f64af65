#!/usr/bin/env bash
# The GPU check of the training path (docs/scale.md), as one short script for a lent GPU machine:
#  1. throughput: data (CPU) against network (GPU) per step, at 1×, 4× and 16× the batch, for the
#     shipped architecture and the grown one (bench/train_throughput.py);
#  2. `train --device cuda` as one process, and under torchrun (DDP over nccl, one rank);
#  3. the first steps' losses on the GPU against the same steps on the CPU (same data, same start);
#  4. steps per second of a real run on the GPU with and without data workers (train.data_workers).
# Usage: bash bench/gpu_check.sh OUTDIR [DEVICE]   (DEVICE: cuda, or cpu to rehearse it here;
# SCALES="1" STEPS=3 CACHE=.cache/specgen make a rehearsal short and reuse this checkout's renders)
set -uo pipefail
OUT=${1:?usage: bench/gpu_check.sh OUTDIR [cuda|cpu]}
DEV=${2:-cuda}
PY=${PYTHON:-python3}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1 | tee "$OUT/machine.txt"
$PY -c "import sys, torch, numpy; print('python', sys.version.split()[0], 'torch', torch.__version__, 'numpy', numpy.__version__, 'cuda', torch.cuda.is_available())" 2>&1 | tee -a "$OUT/machine.txt"
$PY - "$WORK/tiny.json" <<'PYEOF'
import json, os, sys
c = json.load(open("configs/continue_s11_trunk.json"))
c["train"].update(corpus_size=64, steps=60, checkpoint_every=30, val_every=30, val_materials=8,
                  render_workers=8, threads=4, init_weights=os.path.abspath("weights/specgen_default.pt"))
json.dump(c, open(sys.argv[1], "w"))
c["train"].update(steps=int(os.environ.get("TIMED_STEPS", "400")), data_workers=12)
json.dump(c, open(sys.argv[1].replace("tiny", "timed"), "w"))
PYEOF
export SPECGEN_CACHE_DIR=${CACHE:-$WORK/cache}
$PY bench/train_throughput.py --device "$DEV" --threads 4 --corpus-size 64 --render-workers 8 \
    --batch-scale ${SCALES:-1 4 16} --steps ${STEPS:-20} --model-override '{"trunk_upsample_stages": 0}' \
    --model-override '{"image_size": 128, "encoder_channels": [32, 64, 96, 128, 192], "decoder_channels": [128, 96, 64, 64], "head_channels": 48}' \
    --cache "$SPECGEN_CACHE_DIR/train-data" --json "$OUT/throughput.json" 2>&1 | grep -v "it/s\|step/s" | tee "$OUT/throughput.log"
for d in cpu "$DEV"; do
  [ -d "$WORK/single_$d" ] || $PY -m specgen_addon train --config "$WORK/tiny.json" --out "$WORK/single_$d" \
      --device "$d" --steps 5 --quiet 2>&1 | tail -3
done
$PY -m specgen_addon train --config "$WORK/tiny.json" --out "$WORK/single" --device "$DEV" --quiet 2>&1 | tail -3
$PY -m torch.distributed.run --standalone --nproc_per_node 1 -m specgen_addon train --config "$WORK/tiny.json" \
    --out "$WORK/ddp" --device "$DEV" --quiet 2>&1 | tail -3
for w in 0 12; do
  $PY - "$WORK/timed.json" "$w" <<'PYEOF'
import json, sys
c = json.load(open(sys.argv[1])); c["train"]["data_workers"] = int(sys.argv[2])
json.dump(c, open(sys.argv[1].replace(".json", f"_{sys.argv[2]}.json"), "w"))
PYEOF
  $PY -m specgen_addon train --config "$WORK/timed_$w.json" --out "$WORK/timed_$w" --device "$DEV" --quiet 2>&1 \
      | tail -1 | sed "s/^/data_workers $w: /" | tee -a "$OUT/timed.txt"
done
cp "$WORK/single/history.csv" "$OUT/history_single.csv" 2>/dev/null
cp "$WORK/ddp/history.csv" "$OUT/history_ddp.csv" 2>/dev/null
$PY - "$WORK" "$DEV" <<'PYEOF' 2>&1 | tee "$OUT/compare.txt"
import csv, sys
import torch
w, dev = sys.argv[1], sys.argv[2]
def hist(p):
    return [float(r["loss"]) for r in csv.DictReader(open(p))]
a, b = hist(f"{w}/single_cpu/history.csv"), hist(f"{w}/single_{dev}/history.csv")
print("first 5 losses, cpu :", " ".join(f"{x:.6g}" for x in a))
print(f"first 5 losses, {dev}:", " ".join(f"{x:.6g}" for x in b))
print("largest relative difference:", max(abs(x - y) / abs(x) for x, y in zip(a, b)))
s, d = hist(f"{w}/single/history.csv"), hist(f"{w}/ddp/history.csv")
print(f"60 steps on {dev}: single process final loss {s[-1]:.6g}, torchrun (1 rank) {d[-1]:.6g}")
ws = torch.load(f"{w}/single/specgen.pt", map_location="cpu", weights_only=True)
wd = torch.load(f"{w}/ddp/specgen.pt", map_location="cpu", weights_only=True)
sd_s, sd_d = ws.get("state_dict", ws), wd.get("state_dict", wd)
diff = max(float((sd_s[k].float() - sd_d[k].float()).abs().max()) for k in sd_s if torch.is_tensor(sd_s[k]))
print("largest weight difference single vs torchrun after 60 steps:", diff)
PYEOF
