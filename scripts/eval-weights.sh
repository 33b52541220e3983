#!/usr/bin/env bash
# The evaluation battery a candidate set of weights has to pass before it is embedded
# (docs/model-card.md: a new net must hold on every set, in and out of the generator's distribution).
#
#   scripts/eval-weights.sh OUT_DIR NAME=WEIGHTS [NAME=WEIGHTS ...]
#
# WEIGHTS is a folder with irn/msn/envmap.safetensors (as `picker eval --weights DIR` reads it), or
# `embedded` for the weights compiled into the binary. For each candidate NAME it writes
# OUT_DIR/NAME/<set>.json (`picker eval --json-out`) for the sets below, OUT_DIR/NAME/test-metrics.json
# (`python -m training.evaluate`, when PYTHON has torch), and the report sheets of the model card's real
# photos under OUT_DIR/photos/NAME/ (to look at); then prints the tables of scripts/eval_summary.py.
# A result already in OUT_DIR is kept (an interrupted run continues): use a fresh OUT_DIR for new weights.
#
# Sets (made once by `picker synth`, kept in EVAL_DATA, default ./eval-data; none is a training seed):
#   test100     the first 100 scenes of the test split (seed 4242, photographic assets)
#   proc-4242, proc-9191, proc-6161   40 scenes each, procedural textures and skies only
#   assets-5151 40 scenes, photographic assets
#   wide-7171   40 scenes, photographic assets, `--views wide` (views down at floors and tables, close-ups)
#   blender     BLENDER_SCENES (a scripts/blender-scenes.sh output folder), when given
# The test split for training.evaluate: 300 scenes of seed 4242 (EVAL_DATA/test).
#
# Environment: PICKER (default target/release/picker), PYTHON (default python3), ASSETS (default ./assets),
# EVAL_DATA, BLENDER_SCENES, THREADS (default 2), PHOTOS (default 1: run the real photos; needs
# apt-get download of opencv-doc, as scripts/model-card-photos.sh).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="$(mkdir -p "${1:?usage: eval-weights.sh OUT_DIR NAME=WEIGHTS ...}" && cd "$1" && pwd)"
shift
[ $# -ge 1 ] || { echo "eval-weights: give at least one NAME=WEIGHTS (WEIGHTS a folder or 'embedded')" >&2; exit 2; }
PICKER="${PICKER:-$ROOT/target/release/picker}"
PYTHON="${PYTHON:-python3}"
ASSETS="${ASSETS:-$ROOT/assets}"
EVAL_DATA="$(mkdir -p "${EVAL_DATA:-$ROOT/eval-data}" && cd "${EVAL_DATA:-$ROOT/eval-data}" && pwd)"
THREADS="${THREADS:-2}"
cd "$ROOT"
[ -x "$PICKER" ] || { echo "eval-weights: no picker binary at $PICKER" >&2; exit 1; }
[ -d "$ASSETS/textures" ] || { echo "eval-weights: no assets in $ASSETS; run scripts/fetch-assets.sh" >&2; exit 1; }
for c in "$@"; do
    name="${c%%=*}" w="${c#*=}"
    [[ "$c" == *=* && "$name" =~ ^[A-Za-z0-9_.-]+$ ]] || { echo "eval-weights: '$c' is not NAME=WEIGHTS" >&2; exit 2; }
    [ "$w" = embedded ] || [ -d "$w" ] || { echo "eval-weights: $name: no weights folder $w" >&2; exit 2; }
done

gen() {  # DIR SEED COUNT [assets] [VIEWS]
    [ -f "$1/.done" ] && return 0
    rm -rf "$1"
    local a=()
    if [ "${4:-}" = assets ]; then a=(--assets "$ASSETS"); fi
    "$PICKER" synth --count "$3" --size 240x320 --seed "$2" "${a[@]}" --views "${5:-room}" --out "$1" \
        --threads "$THREADS" > "$1.log" 2>&1
    touch "$1/.done"
}
gen "$EVAL_DATA/test" 4242 300 assets
if [ ! -d "$EVAL_DATA/test100" ]; then
    mkdir -p "$EVAL_DATA/test100.tmp"
    for i in $(seq -f "%06g" 0 99); do ln -s "$EVAL_DATA/test/scene_$i" "$EVAL_DATA/test100.tmp/scene_$i"; done
    mv "$EVAL_DATA/test100.tmp" "$EVAL_DATA/test100"
fi
for s in 4242 9191 6161; do gen "$EVAL_DATA/proc-$s" $s 40; done
gen "$EVAL_DATA/assets-5151" 5151 40 assets
gen "$EVAL_DATA/wide-7171" 7171 40 assets wide
SETS=(test100 proc-4242 proc-9191 proc-6161 assets-5151 wide-7171)
declare -A DIRS=([test100]="$EVAL_DATA/test100" [proc-4242]="$EVAL_DATA/proc-4242" [proc-9191]="$EVAL_DATA/proc-9191"
                 [proc-6161]="$EVAL_DATA/proc-6161" [assets-5151]="$EVAL_DATA/assets-5151"
                 [wide-7171]="$EVAL_DATA/wide-7171")
if [ -n "${BLENDER_SCENES:-}" ]; then SETS+=(blender); DIRS[blender]="$BLENDER_SCENES"; fi

PHOTO_DATA=""
if [ "${PHOTOS:-1}" = 1 ]; then
    PHOTO_DATA="$EVAL_DATA/opencv-doc/usr/share/doc/opencv-doc/examples/data"
    if [ ! -d "$PHOTO_DATA" ]; then
        (cd "$EVAL_DATA" && apt-get download opencv-doc > /dev/null && dpkg -x opencv-doc_*.deb opencv-doc)
    fi
    SKIMAGE_DATA="$EVAL_DATA/skimage/skimage/data"
    if [ ! -d "$SKIMAGE_DATA" ]; then
        (cd "$EVAL_DATA" && "$PYTHON" -m pip download --no-deps -q scikit-image==0.26.0 -d skimage \
            && unzip -q skimage/*.whl 'skimage/data/*' -d skimage)
    fi
fi

for c in "$@"; do
    name="${c%%=*}" w="${c#*=}"
    # picker eval needs --embedded for the built-in weights; picker extract runs them when no --weights is given.
    if [ "$w" = embedded ]; then W=(--embedded); WX=(); else W=(--weights "$w"); WX=(--weights "$w"); fi
    mkdir -p "$OUT/$name"
    for s in "${SETS[@]}"; do
        [ -f "$OUT/$name/$s.json" ] && continue
        "$PICKER" eval "${DIRS[$s]}" "${W[@]}" --threads "$THREADS" --json-out "$OUT/$name/$s.json" > /dev/null
        echo "eval-weights: $name $s done"
    done
    if [ -f "$OUT/$name/test-metrics.json" ]; then
        :
    elif "$PYTHON" -c 'import torch' 2> /dev/null; then
        if [ "$w" = embedded ]; then wd="$ROOT/crates/picker-weights/weights"; else wd="$w"; fi
        "$PYTHON" -m training.evaluate --weights "$wd/irn.safetensors" --weights "$wd/msn.safetensors" \
            --weights "$wd/envmap.safetensors" --data "$EVAL_DATA/test" --threads "$THREADS" \
            --out "$OUT/$name/test-metrics.json" > /dev/null
    else
        echo "eval-weights: $PYTHON has no torch: no test-split metrics" >&2
    fi
    if [ -n "$PHOTO_DATA" ]; then
        while read -r photo_name photo pick; do
            "$PICKER" extract "$photo" --pick "$pick" "${WX[@]}" --out "$OUT/photos/$name/$photo_name" \
                --no-timings --threads "$THREADS" > /dev/null
        done < <(grep -v '^#' scripts/model-card-photos.txt \
            | sed -e "s|OPENCV_DATA|$PHOTO_DATA|" -e "s|SKIMAGE_DATA|$SKIMAGE_DATA|")
    fi
done
python3 "$ROOT/scripts/eval_summary.py" "$OUT"
