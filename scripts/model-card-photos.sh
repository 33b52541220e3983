#!/usr/bin/env bash
# The real-photo pictures of docs/model-card.md: `picker extract` with the embedded default weights on
# photographs the networks never saw (Debian's opencv-doc sample images, scikit-image's from PyPI and the
# repository's coffee.jpg),
# each report sheet saved as a JPEG under docs/model-card/.
#
#   scripts/model-card-photos.sh
#
# Requirements: cargo, apt-get + dpkg (opencv-doc is downloaded, not installed), python3 with Pillow and
# pip, unzip (PYTHON=... to choose the interpreter).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PYTHON="${PYTHON:-python3}"
cd "$ROOT"
cargo build --release -p picker-cli
PICKER="${CARGO_TARGET_DIR:-$ROOT/target}/release/picker"

TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
(cd "$TMP" && apt-get download opencv-doc >/dev/null && dpkg -x opencv-doc_*.deb pkg)
DATA="$TMP/pkg/usr/share/doc/opencv-doc/examples/data"
# scikit-image's sample photographs (the wheel's data folder; nothing is installed).
(cd "$TMP" && "$PYTHON" -m pip download --no-deps -q scikit-image==0.26.0 -d sk && unzip -q sk/*.whl 'skimage/data/*' -d sk)
SKDATA="$TMP/sk/skimage/data"

OUT="$ROOT/docs/model-card"
mkdir -p "$OUT"
# name photo pick (scripts/model-card-photos.txt)
while read -r name photo pick; do
    "$PICKER" extract "$photo" --pick "$pick" --out "$TMP/$name" --no-timings --threads 2
    "$PYTHON" - "$TMP/$name/report.png" "$OUT/$name.jpg" <<'EOF'
import sys
from PIL import Image
im = Image.open(sys.argv[1]).convert("RGB")
im.save(sys.argv[2], quality=82, optimize=True)
EOF
done < <(grep -v '^#' scripts/model-card-photos.txt | sed -e "s|OPENCV_DATA|$DATA|" -e "s|SKIMAGE_DATA|$SKDATA|")
echo "model-card-photos: wrote $(ls "$OUT"/*.jpg | wc -l) pictures to $OUT"
