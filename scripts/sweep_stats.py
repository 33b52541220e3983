#!/usr/bin/env python3
"""Summary of a real-photo sweep (scripts/real-photo-sweep.sh): per output
folder, the textured picks, how their wrap edges were made tileable (both
edges cut, one, none, no cut needed), how many got an inpainted band, the
share of the texture's texels holding observed colours (`observed_kept`),
the wrap seam ratio, the texture side and the picks folded to a measured
period. Standard library only.

    python3 scripts/sweep_stats.py OUT [OTHER_OUT...]
    python3 scripts/sweep_stats.py --size PHOTO     # prints "WIDTH HEIGHT" (PNG or JPEG)
"""
import glob
import json
import statistics
import struct
import sys


def image_size(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return struct.unpack(">II", data[16:24])
    if data[:2] == b"\xff\xd8":
        i = 2
        while i + 9 < len(data):
            if data[i] != 0xFF:
                i += 1
                continue
            marker = data[i + 1]
            if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
                i += 2
                continue
            length = struct.unpack(">H", data[i + 2 : i + 4])[0]
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                h, w = struct.unpack(">HH", data[i + 5 : i + 9])
                return w, h
            i += 2 + length
    raise SystemExit(f"{path}: not a PNG or JPEG this script can measure")


def quantile(v, p):
    v = sorted(v)
    return v[int(p * (len(v) - 1))]


def summary(root):
    kept, seam, size = [], [], []
    edges = {"both": 0, "one": 0, "none": 0, "not needed": 0}
    band = period = 0
    for m in glob.glob(f"{root}/*/material_*/material.json"):
        d = json.load(open(m))
        diag = d["diagnostics"]
        if diag.get("observed_kept") is None:
            continue
        kept.append(diag["observed_kept"])
        seam.append(d["texture"]["seam"]["ratio"])
        size.append(d["texture"]["width"])
        cut = diag.get("seam_cut")
        if cut is None:
            edges["not needed"] += 1
        else:
            k = (cut["columns"] is not None) + (cut["rows"] is not None)
            edges[["none", "one", "both"][k]] += 1
        band += diag.get("seam_band") is not None
        period += (diag.get("uv") or {}).get("period") is not None
    if not kept:
        return f"{root}: no textured picks"
    return (
        f"{root}: {len(kept)} textured picks; edges cut {edges}; band {band}; "
        f"observed kept median {statistics.median(kept):.3f} (q10 {quantile(kept, 0.1):.3f}, "
        f"mean {statistics.mean(kept):.3f}); wrap seam ratio median {statistics.median(seam):.2f} "
        f"(q90 {quantile(seam, 0.9):.2f}); side median {statistics.median(size)}; "
        f"folded to a period {period}"
    )


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--size":
        print(*image_size(sys.argv[2]))
    elif len(sys.argv) >= 2:
        for root in sys.argv[1:]:
            print(summary(root))
    else:
        raise SystemExit(__doc__)
