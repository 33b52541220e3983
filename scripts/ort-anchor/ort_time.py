#!/usr/bin/env python3
"""Times one ONNX model with onnxruntime on the CPU and prints one JSON line.

    python ort_time.py MODEL.onnx --threads 2 --runs 5 --warmup 2

Meant to run in its own process (bench_vs_ort.py starts one per round), so ``peak_rss_mb`` (ru_maxrss) is
the peak of this configuration alone: interpreter, onnxruntime, weights and activations.
Session: CPUExecutionProvider, intra_op_num_threads = N, inter_op_num_threads = 1, sequential execution,
all graph optimisations. Input: uniform [-1, 1), seed 0.
"""

import argparse
import json
import resource
import statistics
import time

import numpy as np
import onnxruntime as ort


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("model")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=2)
    args = ap.parse_args()

    options = ort.SessionOptions()
    options.intra_op_num_threads = args.threads
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    t0 = time.perf_counter()
    session = ort.InferenceSession(args.model, options, providers=["CPUExecutionProvider"])
    create_s = time.perf_counter() - t0

    inp = session.get_inputs()[0]
    feed = {inp.name: np.random.default_rng(0).uniform(-1, 1, size=inp.shape).astype(np.float32)}
    for _ in range(args.warmup):
        outputs = session.run(None, feed)
    times = []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        outputs = session.run(None, feed)
        times.append((time.perf_counter() - t0) * 1e3)

    result = dict(
        engine="onnxruntime", version=ort.__version__, threads=args.threads, runs=args.runs,
        warmup=args.warmup, times_ms=times, median_ms=statistics.median(times), min_ms=min(times),
        session_create_s=create_s, peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        outputs={o.name: dict(shape=list(v.shape), finite=bool(np.isfinite(v).all()), std=float(v.std()))
                 for o, v in zip(session.get_outputs(), outputs)})
    print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
