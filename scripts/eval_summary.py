"""One table from the JSON files of scripts/eval-weights.sh (no third-party packages).

    python3 scripts/eval_summary.py OUT_DIR

OUT_DIR holds, per candidate NAME, ``NAME/<set>.json`` (``picker eval --json-out``) and optionally
``NAME/test-metrics.json`` (``python -m training.evaluate``). Prints one Markdown table per figure, a row
per set and a column per candidate, so that a candidate is compared on every set at once.
"""

import json
import os
import sys

EVAL_FIGURES = [
    ("mask IoU, mean", lambda a, r: a["mean_iou"], "{:.3f}"),
    ("materials with IoU >= 0.8", lambda a, r: a["fraction_iou_at_least_0_8"], "{:.1%}"),
    ("flood fill (best), mean IoU", lambda a, r: a["flood_fill_best_mean_iou"], "{:.3f}"),
    # Since stop 30; older JSON files have none (printed as a dash).
    ("segmentation's best tolerance per pick (oracle), mean IoU",
     lambda a, r: a.get("mean_oracle_tolerance_iou"), "{:.3f}"),
    ("texture PSNR, mean over textured (dB)", lambda a, r: a["mean_texture_psnr_db"], "{:.2f}"),
    ("normals at the picks, mean error (deg)", lambda a, r: a["mean_normal_error_deg"], "{:.1f}"),
    ("single-colour materials called textured", lambda a, r: single_called_textured(r), "{}"),
    ("textured materials called textured", lambda a, r: textured_called_textured(r), "{}"),
]

TEST_FIGURES = [
    ("albedo si-MSE improvement", "albedo_si_mse"),
    ("normals improvement", "normals_deg"),
    ("textured/plain accuracy improvement", "uv_t_accuracy"),
    ("env map log-L1 improvement", "envmap_log_l1"),
    ("segmentation L1 improvement", "segmentation_l1"),
]


def single_called_textured(rows):
    plain = [r for r in rows if not r["textured_truth"]]
    return f"{sum(bool(r['textured_extracted']) for r in plain)} / {len(plain)}"


def textured_called_textured(rows):
    tex = [r for r in rows if r["textured_truth"]]
    return f"{sum(bool(r['textured_extracted']) for r in tex)} / {len(tex)}"


def main(argv):
    if len(argv) != 2 or not os.path.isdir(argv[1]):
        sys.exit("usage: python3 scripts/eval_summary.py OUT_DIR (as scripts/eval-weights.sh wrote it)")
    out = argv[1]
    names = sorted(d for d in os.listdir(out) if os.path.isdir(os.path.join(out, d)) and d != "photos")
    if not names:
        sys.exit(f"{out}: no candidate folders")
    sets = sorted({f[:-5] for n in names for f in os.listdir(os.path.join(out, n))
                   if f.endswith(".json") and f != "test-metrics.json"})
    data = {}
    for n in names:
        for s in sets:
            p = os.path.join(out, n, s + ".json")
            if os.path.exists(p):
                with open(p) as f:
                    j = json.load(f)
                data[n, s] = (j["aggregate"], j["rows"])
    for title, get, form in EVAL_FIGURES:
        print(f"\n{title}\n")
        print("| set | " + " | ".join(names) + " |")
        print("|---|" + "---|" * len(names))
        for s in sets:
            cells = []
            for n in names:
                if (n, s) in data:
                    a, r = data[n, s]
                    v = get(a, r)
                    cells.append("–" if v is None else form.format(v))
                else:
                    cells.append("–")
            print(f"| {s} | " + " | ".join(cells) + " |")
    tests = {n: os.path.join(out, n, "test-metrics.json") for n in names}
    tests = {n: p for n, p in tests.items() if os.path.exists(p)}
    if tests:
        print("\ntest split (python -m training.evaluate): model / baseline, improvement\n")
        print("| metric | " + " | ".join(tests) + " |")
        print("|---|" + "---|" * len(tests))
        loaded = {}
        for n, p in tests.items():
            with open(p) as f:
                loaded[n] = json.load(f)["metrics"]
        for title, key in TEST_FIGURES:
            cells = []
            for n in tests:
                m = loaded[n].get(key)
                cells.append("–" if m is None else
                             f"{m['model']:.4g} / {m['baseline']:.4g}, {m['improvement']:.1%}")
            print(f"| {title} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(sys.argv)
