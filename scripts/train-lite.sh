#!/usr/bin/env bash
# The CPU training recipe of the `lite` IRN, MSN and EnvMap (docs/model-card.md): the embedded weights of
# stops 12-28; since stop 29 the embedded MSN is still this recipe's, the IRN and EnvMap scripts/train-gpu.sh's.
#
#   scripts/train-lite.sh [WORK_DIR]        (WORK_DIR defaults to ./lite-work; needs ~25 GB)
#
# Steps, each skipped when its output exists (so a killed run is resumed by running it again):
#   1. data: `picker synth` splits by seed (training 1000000-1000003, validation 900000, test 4242),
#      with the real assets of scripts/fetch-assets.sh. Training scenes are pruned to the files the
#      trainer reads (image.png, material_id.png, scene.json and the element EXRs).
#   2. training: IRN on one core while MSN and then EnvMap train on the other (the 2-core CPU this
#      was made on; `--threads` and the recipes in training/recipes/lite-cpu-*.json say the rest).
#      Interrupted runs continue from their last checkpoint (`--resume`, bit-identical on CPU).
#      With MSN_FT=1, the MSN is then fine-tuned from that run's weights on fresh scenes (seeds
#      1000004 and 1000005, recipe lite-cpu-msn-ft.json, both cores) into runs/lite-msn-ft: the stop-26
#      experiment, which is NOT embedded (better on the synthetic test split, worse on real photos and
#      on procedural-texture scenes; docs/model-card.md). Off by default.
#   3. evaluation: the test-split metrics of docs/model-card.md (python -m training.evaluate and
#      picker eval), written to WORK_DIR/metrics/.
# Then copy WORK_DIR/runs/lite-{irn,msn,envmap}/*.safetensors to crates/picker-weights/weights/ and
# rebuild `picker` to embed them.
#
# Requirements: cargo, python3 with training/requirements.txt (PYTHON=... to choose the interpreter),
# the assets (scripts/fetch-assets.sh).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WORK="$(mkdir -p "${1:-$ROOT/lite-work}" && cd "${1:-$ROOT/lite-work}" && pwd)"
PYTHON="${PYTHON:-python3}"
ASSETS="${ASSETS:-$ROOT/assets}"
cd "$ROOT"

[ -d "$ASSETS/textures" ] || { echo "train-lite: no assets in $ASSETS; run scripts/fetch-assets.sh" >&2; exit 1; }
cargo build --release -p picker-cli
PICKER="${CARGO_TARGET_DIR:-$ROOT/target}/release/picker"

prune() {
    for s in "$1"/scene_*; do
        rm -rf "$s/materials" "$s/depth.exr" "$s/direct_env.exr" "$s/image.exr"
        find "$s" -maxdepth 1 -name '*.png' ! -name image.png ! -name material_id.png -delete
    done
}

# gen SEED COUNT SIZE DIR [prune]
gen() {
    [ -f "$4/.done" ] && return 0
    rm -rf "$4"
    "$PICKER" synth --count "$2" --size "$3" --seed "$1" --assets "$ASSETS" --out "$4" --threads 2
    if [ "${5:-}" = prune ]; then prune "$4"; fi
    touch "$4/.done"
}

D="$WORK/data"
gen 900000 64 240x320 "$D/val"
gen 4242 300 240x320 "$D/test"
for i in 0 1 2; do gen $((1000000 + i)) 2000 120x160 "$D/train-$((1000000 + i))" prune; done
gen 1000003 1000 240x320 "$D/train-1000003" prune

DATA=()
for i in 0 1 2 3; do DATA+=(--data "$D/train-$((1000000 + i))"); done
train() {
    local net=$1 out="$WORK/runs/lite-$1"
    if [ -f "$out/$net.safetensors" ]; then return 0; fi
    if [ -f "$out/checkpoints/last.pt" ]; then
        "$PYTHON" -m training.train --resume --config "training/recipes/lite-cpu-$net.json" --out "$out" --threads 1
    else
        "$PYTHON" -m training.train --net "$net" --preset lite --config "training/recipes/lite-cpu-$net.json" \
            "${DATA[@]}" --val "$D/val" --out "$out" --threads 1
    fi > "$WORK/runs/$net.log" 2>&1
}
mkdir -p "$WORK/runs" "$WORK/metrics"
train irn &
irn=$!
(train msn && train envmap) &
rest=$!
wait "$irn" "$rest"

# MSN fine-tuning (MSN_FT=1 only): fresh Adam from the lite MSN, lower learning rate, new scenes only
# (1135 240×320 scenes: that chunk was cut there to start training in time).
ft="$WORK/runs/lite-msn-ft"
if [ "${MSN_FT:-0}" = 1 ] && [ ! -f "$ft/msn.safetensors" ]; then
    gen 1000004 1135 240x320 "$D/train-1000004" prune
    gen 1000005 6000 120x160 "$D/train-1000005" prune
    if [ -f "$ft/checkpoints/last.pt" ]; then
        "$PYTHON" -m training.train --resume --config training/recipes/lite-cpu-msn-ft.json --out "$ft" --threads 2
    else
        "$PYTHON" -m training.train --net msn --preset lite --init "$WORK/runs/lite-msn/msn.safetensors" \
            --config training/recipes/lite-cpu-msn-ft.json --data "$D/train-1000004" --data "$D/train-1000005" \
            --val "$D/val" --out "$ft" --threads 2
    fi > "$WORK/runs/msn-ft.log" 2>&1
fi

R="$WORK/runs"
"$PYTHON" -m training.evaluate --weights "$R/lite-irn" --weights "$R/lite-msn" --weights "$R/lite-envmap" \
    --data "$D/test" --threads 2 --out "$WORK/metrics/test-metrics.json"
"$PICKER" synth --count 100 --size 240x320 --seed 4242 --assets "$ASSETS" --out "$D/test100" --threads 2
"$PICKER" eval "$D/test100" --weights "$R/lite-irn/irn.safetensors" --weights "$R/lite-msn/msn.safetensors" \
    --weights "$R/lite-envmap/envmap.safetensors" --json-out "$WORK/metrics/picker-eval.json" > "$WORK/metrics/picker-eval.txt"
echo "train-lite: done; metrics in $WORK/metrics, weights in $R/lite-{irn,msn,envmap}/"
