#!/usr/bin/env bash
# An evaluation set from a renderer that is not ours: indoor scenes path-traced by Blender's Cycles
# (global illumination, area and point lamps, a physical sky through a window, Principled BSDF
# materials, Cycles' pixel filter), written as picker scene folders so that `picker eval` measures the
# extraction (ground-truth elements) and the networks (--embedded / --weights) on them.
# See scripts/blender-scenes/README.md.
#
#   scripts/blender-scenes.sh OUT_DIR [COUNT] [SEED]       (defaults: 40 scenes, seed 31337)
#
# Then: picker eval OUT_DIR/scenes --json-out eval.json          (ground-truth elements)
#       picker eval OUT_DIR/scenes --embedded --json-out eval.json
#
# Requirements (Debian): apt-get install blender python3-numpy (Blender's Python is the system one);
# a Python with numpy, Pillow and OpenEXR for the conversion (PYTHON=..., default python3); the
# assets of scripts/fetch-assets.sh (ASSETS=..., default ./assets) for the Sweet Home 3D photographs.
# The GIMP "extras" patterns (gimp-data-extras, never used in training) are downloaded, not installed.
# SAMPLES=256 Cycles samples per pixel (adaptive); about 40 s per 240×320 scene on 2 cores.
# PIXEL_FILTER=blackman-harris (Blender's default, 1.5 px) or box (1 px, as picker synth's samples).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="$(mkdir -p "${1:?usage: blender-scenes.sh OUT_DIR [COUNT] [SEED]}" && cd "$1" && pwd)"
COUNT="${2:-40}"
SEED="${3:-31337}"
PYTHON="${PYTHON:-python3}"
ASSETS="${ASSETS:-$ROOT/assets}"
SAMPLES="${SAMPLES:-256}"
PIXEL_FILTER="${PIXEL_FILTER:-blackman-harris}"
SIZE="${SIZE:-240x320}"

command -v blender >/dev/null || { echo "blender-scenes: no blender (apt-get install blender python3-numpy)" >&2; exit 1; }
[ -d "$ASSETS/textures/sweethome3d" ] || { echo "blender-scenes: no assets in $ASSETS; run scripts/fetch-assets.sh" >&2; exit 1; }

if [ ! -f "$OUT/textures/.done" ]; then
    TMP="$(mktemp -d)"
    trap 'rm -rf "$TMP"' EXIT
    (cd "$TMP" && apt-get download gimp-data-extras >/dev/null && dpkg -x gimp-data-extras_*.deb pkg)
    rm -rf "$OUT/textures"
    "$PYTHON" "$ROOT/scripts/blender-scenes/convert.py" textures --out "$OUT/textures" \
        "sweethome3d=$ASSETS/textures/sweethome3d" \
        "gimp-data-extras=$(echo "$TMP"/pkg/usr/share/gimp/*/patterns)"
    touch "$OUT/textures/.done"
fi

blender -b --factory-startup -noaudio --python-exit-code 1 -P "$ROOT/scripts/blender-scenes/make_scenes.py" -- \
    --out "$OUT/raw" --textures "$OUT/textures" --seed "$SEED" --count "$COUNT" --size "$SIZE" --samples "$SAMPLES" \
    --pixel-filter "$PIXEL_FILTER"
"$PYTHON" "$ROOT/scripts/blender-scenes/convert.py" scenes "$OUT/raw" --out "$OUT/scenes" --seed "$SEED"
echo "blender-scenes: $COUNT scenes in $OUT/scenes"
