#!/usr/bin/env python3
"""A/B timing of `picker bench` configurations in alternating rounds.

The shared 2-core hosts this project is measured on drift by 10-40 % within
minutes, so two builds (or two settings) timed one after the other say
little. This script runs every configuration once per round, round after
round, and reports per configuration the median of its per-round medians and
the geometric mean, over the rounds, of its per-round median (and minimum)
divided by the first configuration's in the same round: a drift that lasts
longer than one round cancels in those ratios.

A configuration is `[ENV=VALUE ...|]BINARY`, e.g.

    python3 scripts/ab-bench.py --net envmap --rounds 12 \\
        /tmp/picker-before \\
        target/release/picker \\
        'PICKER_WINOGRAD_WEIGHTS=packed PICKER_WINOGRAD_TILE=5|target/release/picker'

The first configuration is the baseline. Needs only Python 3 (no packages).
"""

import argparse
import math
import os
import re
import subprocess
import sys

TIMING = re.compile(r"median ([0-9.]+) ms, min ([0-9.]+) ms")


def parse_config(text):
    """`[ENV=VALUE ...|]BINARY` -> (label, env overrides, binary)."""
    env_part, _, binary = text.rpartition("|")
    env = {}
    for item in env_part.split():
        key, sep, value = item.partition("=")
        if not sep or not key:
            sys.exit(f"ab-bench: {text!r}: {item!r} is not ENV=VALUE")
        env[key] = value
    if not binary:
        sys.exit(f"ab-bench: {text!r} names no binary")
    return text, env, binary


def run_once(binary, env, args):
    """One `picker bench` call: (median ms, min ms)."""
    cmd = [
        binary, "bench", "--net", args.net, "--size", args.size,
        "--threads", str(args.threads), "--runs", str(args.runs),
    ]
    full_env = dict(os.environ)
    full_env.update(env)
    try:
        out = subprocess.run(cmd, env=full_env, capture_output=True, text=True)
    except OSError as e:
        sys.exit(f"ab-bench: cannot run {binary}: {e}")
    m = TIMING.search(out.stdout)
    if out.returncode != 0 or m is None:
        sys.exit(f"ab-bench: {' '.join(cmd)} failed ({out.returncode}):\n{out.stderr}{out.stdout}")
    return float(m.group(1)), float(m.group(2))


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("configs", nargs="+", help="[ENV=VALUE ...|]BINARY; the first is the baseline")
    p.add_argument("--net", default="envmap", help="irn, msn or envmap (default envmap)")
    p.add_argument("--size", default="240x320", help="HEIGHTxWIDTH (default 240x320)")
    p.add_argument("--threads", type=int, default=2, help="worker threads (default 2)")
    p.add_argument("--runs", type=int, default=11, help="timed passes per call (default 11)")
    p.add_argument("--rounds", type=int, default=8, help="alternating rounds (default 8)")
    args = p.parse_args()
    if args.rounds < 1 or args.runs < 1:
        sys.exit("ab-bench: --rounds and --runs must be at least 1")
    configs = [parse_config(c) for c in args.configs]
    times = {label: [] for label, _, _ in configs}
    for r in range(args.rounds):
        for label, env, binary in configs:
            times[label].append(run_once(binary, env, args))
        line = "  ".join(f"{times[label][-1][0]:.1f}" for label, _, _ in configs)
        print(f"round {r + 1}/{args.rounds}: medians {line} ms", file=sys.stderr)
    base = times[configs[0][0]]
    print(f"{args.net} {args.size}, {args.threads} threads, {args.rounds} rounds of {args.runs} runs")
    for label, _, _ in configs:
        t = times[label]
        medians = sorted(m for m, _ in t)
        ratio_med = math.exp(sum(math.log(a[0] / b[0]) for a, b in zip(t, base)) / len(t))
        ratio_min = math.exp(sum(math.log(a[1] / b[1]) for a, b in zip(t, base)) / len(t))
        spread = [a[0] / b[0] for a, b in zip(t, base)]
        print(
            f"{label}: median of medians {medians[len(medians) // 2]:.2f} ms; "
            f"vs baseline {ratio_med:.3f} (medians), {ratio_min:.3f} (minima); "
            f"rounds {min(spread):.3f}-{max(spread):.3f}"
        )


if __name__ == "__main__":
    main()
