"""Packs ``picker synth`` output folders for GPU training (:mod:`training.device_data`).

    python -m training.pack SYNTH_DIR --out PACK_DIR [--workers N] [--delete-source]

A pack is a folder of ``.npy`` arrays (8-bit image, uint8 surface mask, float16 element values) and a
``meta.json`` (format, size, count, seeds, scene indices and names); ``--data PACK_DIR`` of
``python -m training.train`` reads it with ``"device_data": true``. ``--delete-source`` removes the synth
folder once the pack is complete (generating in chunks on a small disk).
"""

import argparse
import os
import shutil
import sys
import time

from training import device_data


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m training.pack", description=__doc__.split("\n\n")[0])
    p.add_argument("synth_dir", help="a picker synth --out folder (scenes of one size)")
    p.add_argument("--out", required=True, help="pack folder to create (must not exist)")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="reader processes")
    p.add_argument("--delete-source", action="store_true", help="remove SYNTH_DIR after packing")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    try:
        meta = device_data.pack(args.synth_dir, args.out, workers=args.workers)
    except (ValueError, FileNotFoundError, FileExistsError) as e:
        sys.exit(f"pack: {e}")
    if args.delete_source:
        shutil.rmtree(args.synth_dir)
    print(f"packed {meta['count']} scenes ({meta['height']}x{meta['width']}) into {args.out} "
          f"in {time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main()
