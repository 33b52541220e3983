#!/usr/bin/env bash
# The real-photo sweep the README's figures quote (stops 49-51): a grid of
# 5 x 4 picks on each of 24 OpenCV sample photos (Debian's `opencv-doc`) and
# the two examples, one `picker extract` per photo, then a summary of the
# textures (scripts/sweep_stats.py). About 5 minutes on 2 cores.
#
#   scripts/real-photo-sweep.sh OUT [picker extract flags...]
#   python3 scripts/sweep_stats.py OUT [OTHER_OUT...]
#
# PICKER (default target/release/picker) is the binary; OPENCV_DATA the
# folder of opencv-doc's sample data (default: downloaded and unpacked under
# $OUT/.opencv-doc with `apt-get download`, which needs `apt-get update`).
set -euo pipefail
out=${1:?usage: real-photo-sweep.sh OUT [picker extract flags...]}
shift
here=$(cd "$(dirname "$0")/.." && pwd)
picker=${PICKER:-$here/target/release/picker}
mkdir -p "$out"
data=${OPENCV_DATA:-}
if [ -z "$data" ]; then
  data=$out/.opencv-doc/pkg/usr/share/doc/opencv-doc/examples/data
  if [ ! -d "$data" ]; then
    mkdir -p "$out/.opencv-doc"
    (cd "$out/.opencv-doc" && apt-get download opencv-doc >/dev/null && dpkg-deb -x opencv-doc_*.deb pkg)
  fi
fi
photos=("$here/fixtures/examples/room.png" "$here/fixtures/examples/coffee.jpg")
for n in aloeL.jpg stuff.jpg left01.jpg left03.jpg left07.jpg left12.jpg basketball1.png left.jpg \
         rubberwhale1.png home.jpg fruits.jpg pic1.png smarties.png sudoku.png cards.png messi5.jpg \
         board.jpg chessboard.png building.jpg box_in_scene.png graf1.png leuvenA.jpg baboon.jpg \
         starry_night.jpg; do
  photos+=("$data/$n")
done
for f in "${photos[@]}"; do
  name=$(basename "$f"); name=${name%.*}
  read -r w h < <(python3 "$here/scripts/sweep_stats.py" --size "$f")
  picks=()
  for i in 1 2 3 4 5; do for j in 1 2 3 4; do
    picks+=(--pick "$((w * i / 6)),$((h * j / 5))")
  done; done
  "$picker" extract "$f" "${picks[@]}" --out "$out/$name" --threads 2 "$@" >"$out/$name.log" 2>&1 \
    || echo "failed: $name (see $out/$name.log)"
done
python3 "$here/scripts/sweep_stats.py" "$out"
