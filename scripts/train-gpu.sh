#!/usr/bin/env bash
# The GPU training recipe of the `lite` IRN, MSN and EnvMap (docs/model-card.md): data, packs, three runs.
# The embedded IRN and EnvMap (stop 29) come from it; its MSN was not embedded (docs/model-card.md).
#
#   scripts/train-gpu.sh WORK_DIR
#
# Made for one machine with a CUDA GPU and many cores, run in one go (e.g. a lent GPU machine with a
# deadline): all data are generated there with `picker synth` and packed (training/pack.py), the three
# nets train at once on the one GPU with the scenes held in its memory (recipes training/recipes/gpu-*.json:
# stages of seconds, bf16, photometric augmentation), and everything the run made is left in WORK_DIR/runs.
#
# Data (seeds never used by earlier runs or by the test split 4242):
#   validation  900000               64 scenes 240x320 (synth folder, as train-lite.sh)
#   training    1000020, 1000021     2 x 500 scenes 240x320  (the 240x320 stage)
#               1000010 ... 1000019  chunks of 2000 scenes 120x160, generated until DATA_SECONDS have passed
#                                    (at least MIN_CHUNKS, at most MAX_CHUNKS chunks)
# Environment: PICKER (binary, default target/release/picker), PYTHON (default python3), ASSETS (default
# ./assets), THREADS (default: all cores), DATA_SECONDS (default 75), MIN_CHUNKS (3), MAX_CHUNKS (10),
# CHUNK (2000), CHUNK240 (500), VAL (64), RECIPES (default training/recipes/gpu), DEADLINE (seconds from the
# start after which the trainers are stopped and their last checkpoints exported; default 0 = none).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WORK="$(mkdir -p "${1:?usage: train-gpu.sh WORK_DIR}" && cd "$1" && pwd)"
PICKER="${PICKER:-$ROOT/target/release/picker}"
PYTHON="${PYTHON:-python3}"
ASSETS="${ASSETS:-$ROOT/assets}"
THREADS="${THREADS:-$(nproc)}"
DATA_SECONDS="${DATA_SECONDS:-75}"
MIN_CHUNKS="${MIN_CHUNKS:-3}"
MAX_CHUNKS="${MAX_CHUNKS:-10}"
CHUNK="${CHUNK:-2000}"
CHUNK240="${CHUNK240:-500}"
VAL="${VAL:-64}"
RECIPES="${RECIPES:-$ROOT/training/recipes/gpu}"
DEADLINE="${DEADLINE:-0}"
START=$SECONDS
cd "$ROOT"

[ -x "$PICKER" ] || { echo "train-gpu: no picker binary at $PICKER" >&2; exit 1; }
[ -d "$ASSETS/textures" ] || { echo "train-gpu: no assets in $ASSETS; run scripts/fetch-assets.sh" >&2; exit 1; }
"$PYTHON" -c 'import torch, OpenEXR; print("torch", torch.__version__, "cuda", torch.cuda.is_available())'

D="$WORK/data"
mkdir -p "$D/packs" "$WORK/runs"
synth() {  # SEED COUNT SIZE DIR
    "$PICKER" synth --count "$2" --size "$3" --seed "$1" --assets "$ASSETS" --out "$4" --threads "$THREADS" \
        > "$4.log" 2>&1 || { cat "$4.log" >&2; return 1; }
    tail -n 1 "$4.log"
}
pack_bg() {  # SEED (packs $D/s-SEED into $D/packs/SEED in the background, deleting the synth folder)
    "$PYTHON" -m training.pack "$D/s-$1" --out "$D/packs/$1" --workers 4 --delete-source &
    PACKS+=($!)
}
PACKS=()
[ -f "$D/val/.done" ] || { rm -rf "$D/val"; synth 900000 "$VAL" 240x320 "$D/val"; touch "$D/val/.done"; }
for seed in 1000020 1000021; do
    [ -d "$D/packs/$seed" ] && continue
    rm -rf "$D/s-$seed"; synth $seed "$CHUNK240" 240x320 "$D/s-$seed"; pack_bg $seed
done
t_data=$SECONDS
n=0
for seed in $(seq 1000010 $((1000010 + MAX_CHUNKS - 1))); do
    if [ $n -ge "$MIN_CHUNKS" ] && [ $((SECONDS - t_data)) -ge "$DATA_SECONDS" ]; then break; fi
    n=$((n + 1))
    [ -d "$D/packs/$seed" ] && continue
    rm -rf "$D/s-$seed"; synth "$seed" "$CHUNK" 120x160 "$D/s-$seed"; pack_bg "$seed"
done
for p in "${PACKS[@]}"; do wait "$p"; done
DATA=()
for p in "$D"/packs/*; do DATA+=(--data "$p"); done
echo "train-gpu: data ready after $((SECONDS - START)) s: ${#DATA[@]} packs ($(du -sh "$D/packs" | cut -f1))"

PIDS=()
for net in irn msn envmap; do
    out="$WORK/runs/$net"
    if [ -f "$out/$net.safetensors" ]; then continue; fi
    if [ -f "$out/checkpoints/last.pt" ]; then
        "$PYTHON" -m training.train --resume --out "$out" --threads 4 > "$WORK/runs/$net.log" 2>&1 &
    else
        "$PYTHON" -m training.train --net $net --preset lite --config "$RECIPES-$net.json" "${DATA[@]}" \
            --val "$D/val" --out "$out" --threads 4 > "$WORK/runs/$net.log" 2>&1 &
    fi
    PIDS+=($!)
done
if [ "$DEADLINE" -gt 0 ]; then
    ( while [ $((SECONDS - START)) -lt "$DEADLINE" ]; do sleep 2; done
      echo "train-gpu: deadline reached, stopping the trainers" >&2; kill -INT "${PIDS[@]}" 2>/dev/null ) &
    WATCH=$!
fi
status=0
for p in "${PIDS[@]}"; do wait "$p" || status=1; done
[ -n "${WATCH:-}" ] && kill "$WATCH" 2>/dev/null || true
for net in irn msn envmap; do
    out="$WORK/runs/$net"
    if [ ! -f "$out/$net.safetensors" ] && [ -f "$out/checkpoints/last.pt" ]; then
        echo "train-gpu: $net did not finish; exporting its last checkpoint" >&2
        "$PYTHON" -m training.train --export-only --out "$out" || true
    fi
    tail -n 3 "$WORK/runs/$net.log"
done
echo "train-gpu: done after $((SECONDS - START)) s"
exit $status
