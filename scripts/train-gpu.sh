#!/usr/bin/env bash
# The GPU training recipe of the `lite` IRN, MSN and EnvMap (docs/model-card.md): data, packs, three runs.
# The embedded IRN and EnvMap (stop 29) come from its first version (commit b823f05: all data made before
# training, every chunk with the photographic assets); its MSN was not embedded (docs/model-card.md).
#
#   scripts/train-gpu.sh WORK_DIR
#
# Made for one machine with a CUDA GPU and many cores, run in one go (e.g. a lent GPU machine with a
# deadline): all data are generated there with `picker synth` and packed (training/pack.py), the three
# nets train at once on the one GPU with the scenes held in its memory (recipes training/recipes/gpu-*.json:
# stages of seconds, bf16, photometric augmentation), and everything the run made is left in WORK_DIR/runs
# (the three exported files also together in WORK_DIR/runs/weights, for `--weights` and eval-weights.sh).
#
# Data (seeds never used by earlier runs or by the test split 4242). Chunks of even seed offset use the
# photographic assets (ASSETS), odd ones procedural textures and skies only, so that neither kind is all
# the nets see:
#   validation  900000               64 scenes 240x320 (synth folder, as train-lite.sh)
#   training    1000010 ... 1000019  chunks of CHUNK scenes 120x160, made before training starts until
#                                    DATA_SECONDS have passed (at least MIN_CHUNKS, at most MAX_CHUNKS)
#               1000020 ...          CHUNKS240 chunks of CHUNK240 scenes 240x320, made while the first
#                                    stage trains (THREADS - 3 threads) and read when the 240x320 stage
#                                    begins (`--stage-data 1`; the trainers wait for them, data_wait_s)
# Environment: PICKER (binary, default target/release/picker), PYTHON (default python3), ASSETS (default
# ./assets), THREADS (default: all cores), DATA_SECONDS (default 75), MIN_CHUNKS (3), MAX_CHUNKS (10),
# CHUNK (2000), CHUNK240 (500), CHUNKS240 (2), VAL (64), RECIPES (default training/recipes/gpu), DEADLINE
# (seconds from the start after which the trainers are stopped and their last checkpoints exported;
# default 0 = none).
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
CHUNKS240="${CHUNKS240:-2}"
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
synth() {  # SEED COUNT SIZE DIR THREADS: photographic assets for even seeds, procedural for odd ones
    local assets=()
    if [ $(($1 % 2)) -eq 0 ]; then assets=(--assets "$ASSETS"); fi
    "$PICKER" synth --count "$2" --size "$3" --seed "$1" "${assets[@]}" --out "$4" --threads "$5" \
        > "$4.log" 2>&1 || { cat "$4.log" >&2; return 1; }
    tail -n 1 "$4.log"
}
chunk() {  # SEED COUNT SIZE THREADS: synth into $D/s-SEED, pack into $D/packs/SEED (renamed into place)
    [ -d "$D/packs/$1" ] && return 0
    rm -rf "$D/s-$1" "$D/packs/$1.tmp"
    synth "$1" "$2" "$3" "$D/s-$1" "$4"
    "$PYTHON" -m training.pack "$D/s-$1" --out "$D/packs/$1" --workers 4 --delete-source
}
if [ ! -f "$D/val/.done" ]; then
    rm -rf "$D/val"; synth 900000 "$VAL" 240x320 "$D/val" "$THREADS"; touch "$D/val/.done"
fi
# The first stage's chunks; each chunk is packed in the background while the next one is made.
t_data=$SECONDS
n=0
PACKS=()
for seed in $(seq 1000010 $((1000010 + MAX_CHUNKS - 1))); do
    if [ $n -ge "$MIN_CHUNKS" ] && [ $((SECONDS - t_data)) -ge "$DATA_SECONDS" ]; then break; fi
    n=$((n + 1))
    [ -d "$D/packs/$seed" ] && continue
    rm -rf "$D/s-$seed" "$D/packs/$seed.tmp"; synth "$seed" "$CHUNK" 120x160 "$D/s-$seed" "$THREADS"
    "$PYTHON" -m training.pack "$D/s-$seed" --out "$D/packs/$seed" --workers 4 --delete-source &
    PACKS+=($!)
done
for p in "${PACKS[@]}"; do wait "$p"; done
DATA=()
for seed in $(seq 1000010 $((1000010 + n - 1))); do DATA+=(--data "$D/packs/$seed"); done
LATER=()
for i in $(seq 0 $((CHUNKS240 - 1))); do LATER+=(--stage-data 1 "$D/packs/$((1000020 + i))"); done
echo "train-gpu: first-stage data ready after $((SECONDS - START)) s: $n chunks ($(du -sh "$D/packs" | cut -f1))"

# The 240x320 chunks, made while the first stage trains (the trainers keep three cores busy).
(
    for i in $(seq 0 $((CHUNKS240 - 1))); do chunk $((1000020 + i)) "$CHUNK240" 240x320 $((THREADS > 4 ? THREADS - 3 : 1)); done
) > "$WORK/data240.log" 2>&1 &
GEN=$!

PIDS=()
for net in irn msn envmap; do
    out="$WORK/runs/$net"
    if [ -f "$out/$net.safetensors" ]; then continue; fi
    if [ -f "$out/checkpoints/last.pt" ]; then
        "$PYTHON" -m training.train --resume --out "$out" --threads 4 > "$WORK/runs/$net.log" 2>&1 &
    else
        "$PYTHON" -m training.train --net $net --preset lite --config "$RECIPES-$net.json" "${DATA[@]}" \
            "${LATER[@]}" --val "$D/val" --out "$out" --threads 4 > "$WORK/runs/$net.log" 2>&1 &
    fi
    PIDS+=($!)
done
if [ "$DEADLINE" -gt 0 ]; then
    ( while [ $((SECONDS - START)) -lt "$DEADLINE" ]; do sleep 2; done
      echo "train-gpu: deadline reached, stopping the trainers and the data" >&2
      kill -INT "${PIDS[@]}" 2>/dev/null; pkill -P "$GEN" 2>/dev/null; kill "$GEN" 2>/dev/null ) &
    WATCH=$!
fi
status=0
wait "$GEN" || { echo "train-gpu: making the 240x320 chunks failed or was stopped" >&2; status=1; }
cat "$WORK/data240.log"
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
# The three files in one folder, as `picker --weights DIR` and scripts/eval-weights.sh read them.
mkdir -p "$WORK/runs/weights"
for net in irn msn envmap; do
    if [ -f "$WORK/runs/$net/$net.safetensors" ]; then cp "$WORK/runs/$net/$net.safetensors" "$WORK/runs/weights/"; fi
done
echo "train-gpu: done after $((SECONDS - START)) s; weights in $WORK/runs/weights"
exit $status
