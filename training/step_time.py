"""Time one training step (forward, L1 loss, backward, Adam) of a net preset on random data.

    python -m training.step_time --net irn --preset lite --size 120x160 --batch 8 --threads 1

Used to size the ``lite`` preset for CPU training (docs/model-card.md). Prints the median of ``--runs``
steps after one warm-up step, in seconds.
"""

import argparse
import statistics
import time

import torch

from training.picker_nets import build
from training.presets import preset
from training.train import parse_size


def step_time(net, config, size, batch, runs, seed=0):
    """Median seconds of one training step of ``net`` built from ``config`` at ``size`` = (H, W)."""
    torch.manual_seed(seed)
    model = build(net, config).train()
    opt = torch.optim.Adam(model.parameters(), 1e-3)
    x = torch.rand(batch, 3, *size) * 2 - 1
    times = []
    for i in range(runs + 1):
        t = time.perf_counter()
        y = model(x)
        outs = y.values() if isinstance(y, dict) else [y]
        loss = sum(o.abs().mean() for o in outs)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if i > 0:
            times.append(time.perf_counter() - t)
    return statistics.median(times)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m training.step_time", description=__doc__.split("\n\n")[0])
    p.add_argument("--net", required=True, choices=("irn", "msn", "envmap"))
    p.add_argument("--preset", default="lite")
    p.add_argument("--size", type=parse_size, default=(120, 160))
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--threads", type=int, default=1)
    a = p.parse_args(argv)
    torch.set_num_threads(a.threads)
    s = step_time(a.net, preset(a.net, a.preset), a.size, a.batch, a.runs)
    print(f"{a.net} {a.preset} {a.size[0]}x{a.size[1]} batch {a.batch}, {a.threads} thread(s): {s:.3f} s per step")


if __name__ == "__main__":
    main()
