#!/usr/bin/env python3
"""Times `picker bench` against onnxruntime on the same networks, in one run, on this machine.

    /tmp/ort/bin/python scripts/ort-anchor/bench_vs_ort.py --net msn envmap --size 240x320 --threads 2 \\
        --runs 5 --rounds 3

For each net (thesis preset, random weights, BatchNorm folded, batch 1):

1. builds the ONNX model once and caches it under ``--cache`` (default /tmp/ort-anchor-cache; never the
   repository: IRN is ~435 MB);
2. per round, times onnxruntime in a fresh subprocess (``ort_time.py``: warm-up, then ``--runs`` timed runs;
   median, min and the subprocess's peak RSS) and then runs the picker command, so machine drift hits both
   engines alike (rounds alternate ort, picker, ort, picker, ...);
3. prints a table and one JSON line with both medians and the ratio picker / onnxruntime per net.

The picker command is a template; ``{net}``, ``{size}``, ``{threads}``, ``{runs}`` and ``{warmup}`` are
substituted, it runs from the repository root and must print one JSON object (its last JSON line counts)
with at least ``median_ms`` and ``min_ms`` (``gflops`` and ``peak_rss_mb`` are shown when present).
Across rounds an engine's median is the median of its per-round medians, its min the overall min and its
peak RSS the largest.
"""

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)
from training.presets import NETS  # noqa: E402

DEFAULT_PICKER_CMD = ("target/release/picker bench --net {net} --size {size} --threads {threads} "
                      "--runs {runs} --json")


def cached_model(net, size, seed, cache):
    """Path of the cached ONNX model for ``net`` at ``size``, and its info; builds it when missing."""
    base = os.path.join(cache, f"{net}_thesis_{size}_seed{seed}")
    path, info_path = base + ".onnx", base + ".json"
    if not (os.path.exists(path) and os.path.exists(info_path)):
        os.makedirs(cache, exist_ok=True)
        print(f"building {path} ...", file=sys.stderr, flush=True)
        subprocess.run([sys.executable, os.path.join(HERE, "onnx_nets.py"), "--net", net, "--size", size,
                        "--seed", str(seed), "--out", path], check=True, stdout=subprocess.DEVNULL)
    with open(info_path) as f:
        return path, json.load(f)


def last_json_object(text, what):
    """The last line of ``text`` that parses as a JSON object."""
    for line in reversed(text.strip().splitlines()):
        try:
            value = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(value, dict):
            return value
    raise RuntimeError(f"{what} printed no JSON object:\n{text}")


def run_checked(argv, what):
    """Runs ``argv`` from the repository root; returns its stdout, or fails with its stderr."""
    try:
        proc = subprocess.run(argv, cwd=REPO, capture_output=True, text=True)
    except FileNotFoundError:
        raise RuntimeError(f"{what}: command not found: {argv[0]} (relative to {REPO}; for the picker, "
                           "run `cargo build --release` first)") from None
    if proc.returncode != 0:
        raise RuntimeError(f"{what} failed ({proc.returncode}): {shlex.join(argv)}\n{proc.stderr}")
    return proc.stdout


def time_ort(model, args):
    argv = [sys.executable, os.path.join(HERE, "ort_time.py"), model, "--threads", str(args.threads),
            "--runs", str(args.runs), "--warmup", str(args.warmup)]
    return last_json_object(run_checked(argv, "onnxruntime"), "ort_time.py")


def time_picker(net, args):
    fields = {"{net}": net, "{size}": args.size, "{threads}": str(args.threads), "{runs}": str(args.runs),
              "{warmup}": str(args.warmup)}
    argv = []
    for word in shlex.split(args.picker_cmd):
        for key, value in fields.items():
            word = word.replace(key, value)
        argv.append(word)
    result = last_json_object(run_checked(argv, "picker"), "the picker command")
    missing = [k for k in ("median_ms", "min_ms") if not isinstance(result.get(k), (int, float))]
    if missing:
        raise RuntimeError(f"picker JSON lacks {missing}: {result}")
    return result


def summarise(rounds):
    """Combines per-round results of one engine: median of medians, overall min, largest peak RSS."""
    rss = [r["peak_rss_mb"] for r in rounds if r.get("peak_rss_mb") is not None]
    gflops = [r["gflops"] for r in rounds if r.get("gflops") is not None]
    return dict(median_ms=statistics.median(r["median_ms"] for r in rounds),
                min_ms=min(r["min_ms"] for r in rounds),
                round_medians_ms=[r["median_ms"] for r in rounds],
                peak_rss_mb=max(rss) if rss else None,
                gflops=statistics.median(gflops) if gflops else None)


def fmt(value, width, decimals):
    """``value`` right-aligned in ``width`` columns, or "-" when it is missing."""
    return f"{'-':>{width}}" if value is None else f"{value:{width}.{decimals}f}"


def main():
    try:
        bench(parse_args())
    except RuntimeError as e:
        sys.exit(f"error: {e}")


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--net", nargs="+", choices=NETS, default=list(NETS), help="nets to time (default all)")
    ap.add_argument("--size", default="240x320", help="input HxW (default 240x320)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=5, help="timed runs per round and engine (>= 5)")
    ap.add_argument("--warmup", type=int, default=2, help="untimed runs before them")
    ap.add_argument("--rounds", type=int, default=1, help="alternating ort/picker rounds per net")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random ONNX weights")
    ap.add_argument("--cache", default="/tmp/ort-anchor-cache", help="where the .onnx models are kept")
    ap.add_argument("--picker-cmd", default=DEFAULT_PICKER_CMD, help="command template for the Rust side")
    ap.add_argument("--ort-only", action="store_true", help="time onnxruntime only")
    args = ap.parse_args()
    if args.runs < 5 or args.rounds < 1 or args.warmup < 1:
        ap.error("need --runs >= 5, --warmup >= 1 and --rounds >= 1")
    return args


def bench(args):
    """Builds or reuses the models, runs the rounds, prints the table and the JSON line."""
    models = {net: cached_model(net, args.size, args.seed, args.cache) for net in args.net}
    results = {net: {"ort": [], "picker": []} for net in args.net}
    for round_index in range(args.rounds):
        for net in args.net:
            ort = time_ort(models[net][0], args)
            results[net]["ort"].append(ort)
            line = f"round {round_index + 1}/{args.rounds} {net}: ort {ort['median_ms']:.1f} ms"
            if not args.ort_only:
                picker = time_picker(net, args)
                results[net]["picker"].append(picker)
                line += f", picker {picker['median_ms']:.1f} ms"
            print(line, file=sys.stderr, flush=True)

    summary = {}
    for net in args.net:
        flops = models[net][1]["flops"]
        ort = summarise(results[net]["ort"])
        ort["gflops"] = flops / ort["median_ms"] / 1e6
        entry = dict(gflop=flops / 1e9, ort=ort)
        if not args.ort_only:
            entry["picker"] = summarise(results[net]["picker"])
            entry["ratio_picker_over_ort"] = entry["picker"]["median_ms"] / ort["median_ms"]
            entry["round_ratios"] = [p["median_ms"] / o["median_ms"]
                                     for p, o in zip(results[net]["picker"], results[net]["ort"])]
        summary[net] = entry

    print(f"\n{args.size}, {args.threads} threads, {args.runs} runs x {args.rounds} rounds, onnxruntime "
          f"{results[args.net[0]]['ort'][0]['version']}")
    header = f"{'net':8s} {'GFLOP':>8s} | {'ort med':>9s} {'min':>9s} {'GFLOP/s':>8s} {'RSS MB':>7s}"
    if not args.ort_only:
        header += f" | {'picker med':>10s} {'min':>9s} {'GFLOP/s':>8s} {'RSS MB':>7s} | {'picker/ort':>10s}"
    print(header)
    print("-" * len(header))
    for net, e in summary.items():
        o = e["ort"]
        row = (f"{net:8s} {e['gflop']:8.1f} | {o['median_ms']:9.1f} {o['min_ms']:9.1f} {o['gflops']:8.1f} "
               f"{fmt(o['peak_rss_mb'], 7, 0)}")
        if not args.ort_only:
            p = e["picker"]
            row += (f" | {p['median_ms']:10.1f} {p['min_ms']:9.1f} {fmt(p['gflops'], 8, 1)} "
                    f"{fmt(p['peak_rss_mb'], 7, 0)} | {e['ratio_picker_over_ort']:10.3f}")
        print(row)
    print(json.dumps(dict(tool="bench_vs_ort", size=args.size, threads=args.threads, runs=args.runs,
                          rounds=args.rounds, ort_version=results[args.net[0]]["ort"][0]["version"],
                          nets=summary)))


if __name__ == "__main__":
    main()
