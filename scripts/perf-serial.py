#!/usr/bin/env python3
"""Where a parallel run leaves cores idle: `perf` samples binned into time windows by thread.

A stretch where only one of the pool's threads takes samples is serial work (or a lock); this
prints, for each window, how many samples it holds against a full window's, the threads that
were busy and its most frequent functions, then the functions of the windows with idle cores,
with the core-time those windows lost. Stop 63 found the 12-MP extraction's serial
full-resolution passes this way.

    perf record -F 2000 -g -o /tmp/p.data target/release/picker extract 12mp.png --pick 2500,1875 --threads 2
    perf script -i /tmp/p.data -F tid,time,ip,sym > /tmp/p.txt
    python3 scripts/perf-serial.py /tmp/p.txt --freq 2000 --threads 2

The label of a sample is its innermost frame whose name mentions `--crate` (default `picker`) and
is not a closure or rayon's plumbing, else its leaf. Needs only Python 3.
"""

import argparse
import collections
import re


def parse(path):
    """(tid, time, frames) per sample of `perf script -F tid,time,ip,sym` output."""
    samples, cur = [], None
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if not line.strip():
                if cur:
                    samples.append(cur)
                cur = None
                continue
            if not line[0].isspace():
                head = line.split()
                try:
                    cur = (int(head[0]), float(head[1].rstrip(":")), [])
                except (IndexError, ValueError):
                    cur = None
                continue
            parts = line.strip().split(None, 1)
            if cur is not None and len(parts) > 1:
                cur[2].append(parts[1])
    if cur:
        samples.append(cur)
    return samples


def label(frames, crate):
    for name in frames:
        if crate in name and "closure" not in name and "rayon" not in name:
            return re.sub(r"<.*", "", name)[:80]
    return (frames[0] if frames else "?")[:80]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("perf_script", help="output of `perf script -F tid,time,ip,sym`")
    ap.add_argument("--freq", type=float, default=2000, help="sampling frequency of `perf record -F`")
    ap.add_argument("--threads", type=int, default=2, help="threads that should be busy")
    ap.add_argument("--window-ms", type=float, default=20, help="window length")
    ap.add_argument("--crate", default="picker", help="name part of the frames to label samples by")
    ap.add_argument("--top", type=int, default=30, help="functions listed in the summary")
    args = ap.parse_args()

    samples = parse(args.perf_script)
    if not samples:
        raise SystemExit(f"{args.perf_script}: no samples")
    t0 = samples[0][1]
    win = args.window_ms / 1000.0
    per_thread = args.freq * win
    windows = collections.defaultdict(list)
    for tid, t, frames in samples:
        windows[int((t - t0) / win)].append((tid, frames))

    lost_ms = 0.0
    idle_labels = collections.Counter()
    print(f"{'t (s)':>7} {'samples':>7}/{per_thread * args.threads:.0f} busy  most frequent")
    for k in range(max(windows) + 1):
        got = windows.get(k, [])
        tids = collections.Counter(tid for tid, _ in got)
        busy = sum(1 for c in tids.values() if c >= per_thread / 2)
        labels = collections.Counter(label(fr, args.crate) for _, fr in got)
        idle = max(0.0, 1.0 - len(got) / (per_thread * args.threads))
        if busy < args.threads:
            lost_ms += idle * args.threads * args.window_ms
            for name, c in labels.items():
                idle_labels[name] += c
        top = ", ".join(f"{n} ({c})" for n, c in labels.most_common(2))
        print(f"{k * win:7.2f} {len(got):7d}  {busy:4d}  {top}")
    print(f"\ncore-time lost in windows with fewer than {args.threads} busy threads: {lost_ms:.0f} ms")
    print("their samples by function (each sample ~{:.2f} ms of one core):".format(1000 / args.freq))
    for name, c in idle_labels.most_common(args.top):
        print(f"{c:7d}  {name}")


if __name__ == "__main__":
    main()
