#!/usr/bin/env python3
"""Writes fixtures/jpeg/: small JPEG files in the codings the `image` crate's
encoder does not write, for the entropy-data check (`picker_extract::jpeg`)
and its tests (crates/picker-extract/tests/jpeg.rs).

Needs Pillow (libjpeg). Deterministic for one Pillow/libjpeg version; the
committed files are what the tests read, this script is how they were made:

    pip install pillow numpy && python3 scripts/make-jpeg-fixtures.py
"""
import io
import pathlib

import numpy as np
from PIL import Image

OUT = pathlib.Path(__file__).resolve().parent.parent / "fixtures" / "jpeg"


def picture(w, h, seed):
    """Smooth waves plus noise: every block has AC coefficients."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    a = np.stack(
        [
            128 + 100 * np.sin(x / 5.0 + y / 7.0),
            128 + 80 * np.cos(x / 3.0),
            100 + 60 * np.sin(y / 4.0),
        ],
        -1,
    ) + rng.normal(0, 12, (h, w, 3))
    return Image.fromarray(np.clip(a, 0, 255).astype(np.uint8))


# name, size (odd: partial MCUs at the right and bottom), mode, save options
CASES = [
    # libjpeg's default progressive script: DC first and refining scans,
    # AC bands with successive approximation (refining AC scans), 4:2:0.
    ("progressive-420.jpg", (57, 41), "RGB", dict(progressive=True, quality=90)),
    ("progressive-grey.jpg", (45, 23), "L", dict(progressive=True, quality=85)),
    # Restart markers every 2 MCUs, 4:4:4 and 4:2:0, sequential and progressive.
    ("restart-444.jpg", (37, 29), "RGB", dict(restart_marker_blocks=2, subsampling=0, quality=92)),
    ("restart-420.jpg", (50, 34), "RGB", dict(restart_marker_blocks=3, subsampling=2, quality=80)),
    ("restart-progressive.jpg", (41, 35), "RGB", dict(progressive=True, restart_marker_blocks=2, quality=88)),
    # Sequential 4:2:2 and optimised Huffman tables (codes of many lengths).
    ("optimised-422.jpg", (61, 27), "RGB", dict(subsampling=1, optimize=True, quality=95)),
]


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    for k, (name, (w, h), mode, opts) in enumerate(CASES):
        img = picture(w, h, k).convert(mode)
        buf = io.BytesIO()
        img.save(buf, "JPEG", **opts)
        (OUT / name).write_bytes(buf.getvalue())
        print(f"{name}: {len(buf.getvalue())} bytes")


if __name__ == "__main__":
    main()
