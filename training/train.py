"""Trainer of the IRN, MSN and EnvMap on ``picker synth`` scenes (issue 5, item 1).

Recipe (thesis / Sengupta et al. 2019): L1 on every element, Adam (lr 1e-3 MSN, 1e-4 IRN, 1e-3 EnvMap),
multi-resolution fine-tuning (stages of sizes and steps, e.g. 120×160 then 240×320). Losses are computed in the
networks' tanh space on targets encoded with the exact inverses of :mod:`training.conventions` (see
:mod:`training.synth_data` for the targets, masks and augmentation): for albedos, glossiness, uv and
segmentation this is 2× the L1 of the decoded values, for normals and view vectors the L1 of the unit
vectors, for the env map the L1 of ln(1 + L) scaled by 2/ln(1001) (a log-radiance loss).

Usage (from the repository root; ``-m`` so that ``training`` is a package)::

    python -m training.train --net msn --preset tiny --data DATA/train --val DATA/val --out runs/msn \\
        --size 120x160 --steps 200 --batch 4
    python -m training.train --resume --out runs/msn [--steps 400]       # continue (bit-identical on CPU)
    python -m training.train --export-only --out runs/msn                # (re)write runs/msn/msn.safetensors
    python -m training.train --net msn --preset lite --init crates/picker-weights/weights/msn.safetensors \
        --data DATA/train --val DATA/val --out runs/msn-ft --config training/recipes/lite-cpu-msn-ft.json
                                                                         # fine-tune a weights file (fresh Adam)

Run folder: ``config.json`` (the effective training config), ``train.csv`` / ``val.csv`` (logs),
``samples/step_NNNNNNN.png`` (input | target | prediction per element for a few fixed scenes),
``checkpoints/last.pt`` (model, optimiser, step, RNG states, elapsed time), and at the end
``<net>.safetensors`` (F16, the documented weights format, loadable by ``picker --weights RUN_DIR``).
"""

import argparse
import copy
import csv
import datetime
import hashlib
import json
import os
import random
import signal
import time

import numpy as np
import torch

from training import device_data
from training import synth_data as sd
from training.embedding import embedding_loss
from training.picker_nets import build, named_outputs, save_weights
from training.presets import PRESETS, preset, validate_config

DEFAULT_LR = {"irn": 1e-4, "msn": 1e-3, "envmap": 1e-3}

DEFAULTS = {
    "net": None,
    "preset": "tiny",          # a preset of training/presets.py, used when "model" is null
    "model": None,             # or a full net config dict (the contract's keys)
    "label": None,             # metadata "preset" of the export; default: the preset name, "custom" for "model"
    "seed": 0,
    "batch": 4,
    "lr": None,                # default DEFAULT_LR[net]
    "adam_betas": [0.9, 0.999],
    "stages": [{"size": [120, 160], "steps": 100}],
    "flip": True,
    "loss_weights": {},        # element → weight (default 1 each)
    "data": [],
    "val": [],
    "val_scenes": 64,          # at most this many validation scenes per evaluation
    "log_every": 10,
    "val_every": 1000,
    "sample_every": 500,
    "sample_scenes": 4,
    "ckpt_every": 1000,
    "workers": 0,
    "cache": False,
    "amp": False,              # bf16 autocast on CUDA
    "export_dtype": "f16",
    "init": None,              # weights file whose tensors start the run (fine-tuning), else random init
    "init_history": None,      # set by the trainer: what the export records about "init" (training.init)
    "device_data": False,      # keep the scenes on the device, batches made there (training/device_data.py)
    "augment": None,           # photometric augmentation of the input (IRN, MSN): {"p", "exposure", ...}
    "channels_last": False,    # NHWC activations on CUDA (faster bf16 convolutions)
    "data_wait_s": 0,          # device_data: how long a stage waits for its "data" to appear (made meanwhile)
}

DTYPES = {"f16": torch.float16, "bf16": torch.bfloat16, "f32": torch.float32}


def parse_size(text):
    """``"120x160"`` → [120, 160] (height × width)."""
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r}: expected HEIGHTxWIDTH, e.g. 120x160") from None
    return [h, w]


def arg_parser():
    p = argparse.ArgumentParser(prog="python -m training.train", description=__doc__.split("\n\n")[0])
    p.add_argument("--net", choices=("irn", "msn", "envmap"))
    p.add_argument("--preset", help="network preset of training/presets.py (tiny, thesis, ...)")
    p.add_argument("--config", help="JSON training config (keys of DEFAULTS; CLI flags override it)")
    p.add_argument("--data", action="append", help="picker synth output folder for training (repeatable)")
    p.add_argument("--val", action="append", help="validation folder (repeatable; seeds disjoint from --data)")
    p.add_argument("--stage-data", nargs=2, action="append", metavar=("STAGE", "DIR"),
                   help="more training data read when stage STAGE (0-based) begins (device_data; repeatable)")
    p.add_argument("--out", required=True, help="run folder")
    p.add_argument("--steps", type=int, help="total steps (the last stage is extended or cut to reach it)")
    p.add_argument("--size", type=parse_size, help="training size HxW: one stage (overrides the config's stages)")
    p.add_argument("--batch", type=int)
    p.add_argument("--lr", type=float)
    p.add_argument("--seed", type=int)
    p.add_argument("--no-flip", action="store_true", help="no random left-right mirroring")
    p.add_argument("--workers", type=int, help="data-loader worker processes")
    p.add_argument("--device", choices=("cpu", "cuda"), help="default: cuda when available")
    p.add_argument("--threads", type=int, help="torch CPU threads")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoints/last.pt")
    p.add_argument("--init", help="start from this weights file's tensors (same net and config; fresh Adam state)")
    p.add_argument("--until", type=int, help="stop (checkpoint, no export) once this step is reached")
    p.add_argument("--export-only", action="store_true", help="export OUT/checkpoints/last.pt and exit")
    p.add_argument("--log-every", type=int)
    p.add_argument("--val-every", type=int)
    p.add_argument("--sample-every", type=int)
    p.add_argument("--ckpt-every", type=int)
    p.add_argument("--quiet", action="store_true")
    return p


def effective_config(args, base=None):
    """DEFAULTS < the checkpoint's config (resume) < --config < flags."""
    cfg = copy.deepcopy(DEFAULTS if base is None else base)
    if args.config:
        with open(args.config) as f:
            user = json.load(f)
        unknown = set(user) - set(DEFAULTS)
        if unknown:
            raise SystemExit(f"{args.config}: unknown keys {sorted(unknown)}; known: {sorted(DEFAULTS)}")
        cfg.update(user)
    flags = {"net": args.net, "preset": args.preset, "batch": args.batch, "lr": args.lr, "seed": args.seed,
             "workers": args.workers, "log_every": args.log_every, "val_every": args.val_every,
             "sample_every": args.sample_every, "ckpt_every": args.ckpt_every}
    for k, v in flags.items():
        if v is not None:
            cfg[k] = v
    if args.preset is not None:
        cfg["model"] = None
    if args.init:
        cfg["init"] = args.init
    if args.data:
        cfg["data"] = args.data
    if args.val:
        cfg["val"] = args.val
    for stage, folder in args.stage_data or []:
        try:
            cfg["stages"][int(stage)].setdefault("data", []).append(folder)
        except (ValueError, IndexError):
            raise SystemExit(f"--stage-data {stage} {folder}: no stage {stage} "
                             f"(the run has {len(cfg['stages'])})") from None
    if args.no_flip:
        cfg["flip"] = False
    if args.size is not None:
        cfg["stages"] = [{"size": args.size, "steps": args.steps or sum(s["steps"] for s in cfg["stages"])}]
    if args.steps is not None:
        cfg["stages"] = set_total_steps(cfg["stages"], args.steps)
    if cfg["net"] not in DEFAULT_LR:
        raise SystemExit("--net irn|msn|envmap is required")
    if cfg["augment"] and cfg["net"] == "envmap":
        raise SystemExit("augment: not for the EnvMap net (an exposure change would have to change its target)")
    if cfg["augment"]:
        known = {"p", "exposure", "white_balance", "noise", "vignette", "blur", "tone", "saturation", "jpeg"}
        unknown = set(cfg["augment"]) - known
        if unknown:
            raise SystemExit(f"augment: unknown keys {sorted(unknown)}; known: {', '.join(sorted(known))}")
    if cfg["lr"] is None:
        cfg["lr"] = DEFAULT_LR[cfg["net"]]
    if cfg["model"] is None:
        cfg["model"] = preset(cfg["net"], cfg["preset"])
        cfg["label"] = cfg["label"] or cfg["preset"]
    else:
        cfg["label"] = cfg["label"] or "custom"
    validate_config(cfg["net"], cfg["model"])
    if cfg["label"] in PRESETS[cfg["net"]] and PRESETS[cfg["net"]][cfg["label"]] != cfg["model"]:
        raise SystemExit(f"label {cfg['label']!r} names a preset but the model config differs from it")
    for s in cfg["stages"]:
        unknown = set(s) - {"size", "steps", "seconds", "lr", "data"}
        if unknown:
            raise SystemExit(f"stage {s}: unknown keys {sorted(unknown)}; known: data, lr, seconds, size, steps")
        if "data" in s and not cfg["device_data"]:
            raise SystemExit(f"stage {s}: stage data needs \"device_data\": true")
        if "steps" not in s and "seconds" not in s:
            raise SystemExit(f"stage {s}: needs steps or seconds")
        if "steps" not in s and not cfg["device_data"]:
            raise SystemExit(f"stage {s}: a stage of seconds needs \"device_data\": true")
        if "steps" not in s and not (isinstance(s["seconds"], (int, float)) and s["seconds"] > 0):
            raise SystemExit(f"stage {s}: seconds must be a positive number")
        if "lr" in s and not (isinstance(s["lr"], (int, float)) and s["lr"] > 0):
            raise SystemExit(f"stage {s}: lr must be a positive number")
        h, w = s["size"]
        if cfg["net"] != "envmap" and (h % 4 or w % 4):
            raise SystemExit(f"training size {h}x{w}: IRN/MSN need multiples of 4")
        if min(h, w) < 16:
            raise SystemExit(f"training size {h}x{w}: at least 16x16")
    if not cfg["data"]:
        raise SystemExit("--data is required")
    return cfg


def set_total_steps(stages, total):
    """Stages cut or extended (the last one) so that their steps sum to ``total``."""
    if any("steps" not in s for s in stages):
        raise SystemExit("--steps: the stages are given in seconds; give them steps instead")
    out, left = [], total
    for s in stages:
        if left <= 0:
            break
        n = min(s["steps"], left)
        out.append({**s, "size": list(s["size"]), "steps": n})
        left -= n
    if left > 0:
        if out:
            out[-1]["steps"] += left
        else:
            out = [{"size": list(stages[-1]["size"]), "steps": left}]
    return out


def stage_lr(cfg, stage):
    """Learning rate of stage ``stage``: its own ``"lr"`` when it has one, else the run's (a step schedule
    is written as stages of one size with different rates)."""
    return cfg["stages"][stage].get("lr", cfg["lr"])


def stage_of(stages, step):
    """(stage index, size) used by step number ``step`` (0-based)."""
    end = 0
    for i, s in enumerate(stages):
        end += s["steps"]
        if step < end:
            return i, tuple(s["size"])
    return len(stages) - 1, tuple(stages[-1]["size"])


class Schedule:
    """Which stage a step is in. A stage has a number of ``steps``, or a training-time budget ``seconds``
    (``device_data`` only): once that much training time is spent, the stage gets the number of steps it took
    (recorded in the config, so the export's recipe and a re-run with it are in steps)."""

    def __init__(self, stages, state=None):
        self.stages = stages
        self.idx, self.start, self.secs = state if state is not None else (0, 0, 0.0)

    def current(self, step):
        """(stage index, size) of step ``step``, or None when every stage is done."""
        while self.idx < len(self.stages):
            s = self.stages[self.idx]
            if "steps" in s:
                done = step - self.start >= s["steps"]
            else:
                done = self.secs >= s["seconds"]
                if done:
                    s["steps"] = step - self.start
            if not done:
                break
            self.start += s["steps"]
            self.idx += 1
            self.secs = 0.0
        if self.idx == len(self.stages):
            return None
        return self.idx, tuple(self.stages[self.idx]["size"])

    def add_time(self, seconds):
        self.secs += seconds

    def state(self):
        return (self.idx, self.start, self.secs)


class StageSize:
    """Training size of global sample number k (a picklable callable for data-loader workers)."""

    def __init__(self, stages, batch):
        self.stages, self.batch = stages, batch

    def __call__(self, k):
        return stage_of(self.stages, k // self.batch)[1]


def sources_until(cfg, stage):
    """Training sources of a device-data run once stage ``stage`` has begun: ``data`` and the stage data of
    stages 0..stage."""
    out = list(cfg["data"])
    for s in cfg["stages"][:stage + 1]:
        out += s.get("data", [])
    return out


def disjoint_seeds(sources, val_seeds):
    """Sorted generator seeds of ``sources``; SystemExit when the validation data share one."""
    seeds = device_data.source_seeds(sources)
    shared = sorted(set(seeds) & set(val_seeds))
    if shared:
        raise SystemExit(f"splits 'train' and 'val' share the picker synth seeds {shared}; "
                         "train, validation and test data must come from different seeds")
    return seeds


def wait_for(folders, seconds, say, stopped=lambda: False):
    """Waits up to ``seconds`` for every folder to exist (a pack appears whole: it is renamed into place);
    SystemExit naming the missing ones after that. Returns False when ``stopped()`` became true first."""
    t_end = time.monotonic() + seconds
    missing = [f for f in folders if not os.path.exists(f)]
    if missing:
        say(f"waiting up to {seconds} s for {missing}")
    while missing and time.monotonic() < t_end:
        if stopped():
            return False
        time.sleep(0.5)
        missing = [f for f in missing if not os.path.exists(f)]
    if missing:
        raise SystemExit(f"stage data {missing}: not there after {seconds} s (data_wait_s)")
    return True


def seed_everything(seed):
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def rng_state():
    return {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state(),
            "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None}


def set_rng_state(s):
    random.setstate(s["python"])
    np.random.set_state(s["numpy"])
    torch.set_rng_state(s["torch"])
    if s.get("cuda") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(s["cuda"])


def atomic_save(obj, path):
    tmp = path + ".tmp"
    torch.save(obj, tmp)
    os.replace(tmp, path)


def elements_of(net, model_config):
    if net == "irn":
        return [h["name"] for h in model_config["heads"]]
    if net == "msn":
        return ["segmentation"] + (["embedding"] if model_config["out_channels"] > 3 else [])
    return ["envmap"]


def to_device(batch, device):
    return {k: v.to(device, non_blocking=True) for k, v in batch.items()}


def losses(net, model, batch, elements, weights):
    """(total, dict element → loss) of one batch (model in its current train/eval mode)."""
    out = named_outputs(net, model(batch["input"]))
    per = {}
    for name in elements:
        if name == "embedding":  # no target of its own: the materials of the target segmentation
            per[name] = embedding_loss(out[name].float(), batch["segmentation"], batch["surface"])
            continue
        if name not in batch:
            raise KeyError(f"the data has no target for head {name!r} (synth writes {sd.IRN_ELEMENTS})")
        per[name] = sd.element_loss(name, out[name].float(), batch)
    total = sum(weights.get(k, 1.0) * v for k, v in per.items())
    return total, per, out


class CsvLog:
    """Appends rows to a CSV file; on resume, rows after the checkpoint's step are dropped first."""

    def __init__(self, path, fields, resume_step=None):
        self.path, self.fields = path, fields
        rows = []
        if resume_step is not None and os.path.exists(path):
            with open(path, newline="") as f:
                rows = [r for r in csv.DictReader(f) if int(r["step"]) <= resume_step]
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fields)
            w.writeheader()
            w.writerows(rows)

    def write(self, row):
        with open(self.path, "a", newline="") as f:
            csv.DictWriter(f, self.fields).writerow(row)


def fmt(v):
    return f"{v:.6g}" if isinstance(v, float) else v


def evaluate_val(net, model, scenes, size, elements, weights, batch, device):
    """Mean losses over validation scenes (eval mode, centre crops, no mirroring)."""
    ds = sd.SynthDataset(scenes, net, 0, lambda k: size, flip=False, crop="centre", shuffle=False)
    sums, count = {}, 0
    was_training = model.training
    model.eval()
    with torch.no_grad():
        for start in range(0, len(scenes), batch):
            items = [ds[k] for k in range(start, min(start + batch, len(scenes)))]
            b = to_device(torch.utils.data.default_collate(items), device)
            total, per, _ = losses(net, model, b, elements, weights)
            n = len(items)
            for k, v in [("loss", total)] + list(per.items()):
                sums[k] = sums.get(k, 0.0) + float(v) * n
            count += n
    model.train(was_training)
    return {k: v / count for k, v in sums.items()}


def save_samples(path, net, model, scenes, size, elements, device):
    """A PNG grid: one row per scene: input, then target | prediction of each element."""
    from PIL import Image  # noqa: PLC0415

    ds = sd.SynthDataset(scenes, net, 0, lambda k: size, flip=False, crop="centre", shuffle=False)
    items = [ds[k] for k in range(len(scenes))]
    b = to_device(torch.utils.data.default_collate(items), device)
    was_training = model.training
    model.eval()
    with torch.no_grad():
        out = named_outputs(net, model(b["input"]))
    model.train(was_training)
    h, w = size

    def full(img):
        img = img.float().cpu()
        if img.shape[-2:] != (h, w):
            img = torch.nn.functional.interpolate(img, size=(h, w), mode="nearest")
        return img

    cols = [sd.picture("input", b["input"].cpu())]
    for name in elements:
        if name == "embedding":  # no target picture: the material labels' colours stand in
            cols += [full(sd.picture("segmentation", b["segmentation"].cpu())),
                     full(sd.picture(name, out[name].float().cpu()))]
            continue
        cols += [full(sd.picture(name, b[name].cpu())), full(sd.picture(name, out[name].float().cpu()))]
    gap = 2
    grid = torch.ones(3, len(items) * (h + gap) - gap, len(cols) * (w + gap) - gap)
    for r in range(len(items)):
        for c, img in enumerate(cols):
            grid[:, r * (h + gap):r * (h + gap) + h, c * (w + gap):c * (w + gap) + w] = img[r]
    arr = (grid.clamp(0, 1).permute(1, 2, 0).numpy() * 255 + 0.5).astype(np.uint8)
    Image.fromarray(arr).save(path)


def read_init(path, net, config):
    """(state dict, metadata) of the weights file that starts a fine-tuning run.

    Refuses a file of another net or config, or one whose tensors do not match the model's keys exactly.
    Floating tensors are returned as f32 (the file may hold F16/BF16).
    """
    from safetensors import safe_open

    if not os.path.exists(path):
        raise SystemExit(f"--init {path}: no such file")
    with safe_open(path, framework="pt") as f:
        meta = f.metadata() or {}
        state = {k: f.get_tensor(k) for k in f.keys()}
    if meta.get("net") != net:
        raise SystemExit(f"--init {path}: holds {meta.get('net')!r} weights, this run trains {net!r}")
    try:
        file_config = json.loads(meta.get("config", "null"))
    except json.JSONDecodeError:
        raise SystemExit(f"--init {path}: metadata 'config' is not JSON") from None
    if file_config != config and not widens(net, file_config, config):
        raise SystemExit(f"--init {path}: config {file_config} differs from the run's {config}")
    return {k: (v.float() if v.is_floating_point() else v) for k, v in state.items()}, meta


def widens(net, file_config, config):
    """Whether a run of ``config`` may start from weights of ``file_config`` by widening the output: an MSN
    that adds material-embedding channels (:mod:`training.embedding`) to the three colours of a file, all else
    equal."""
    if net != "msn" or not isinstance(file_config, dict):
        return False
    rest = {k: v for k, v in file_config.items() if k != "out_channels"}
    return (rest == {k: v for k, v in config.items() if k != "out_channels"}
            and file_config.get("out_channels") == 3 and config["out_channels"] > 3)


def widen_output(state, mine, seed):
    """``state`` with the MSN's ``dec.conv_out`` widened to the shapes of ``mine`` (the run's state dict): the
    file's channels first, the new ones' weights drawn from N(0, 0.01²) (seeded), their biases 0."""
    g = torch.Generator().manual_seed(seed)
    out = dict(state)
    for key in ("dec.conv_out.weight", "dec.conv_out.bias"):
        old, shape = state[key], mine[key].shape
        c = old.shape[0]
        if old.shape[1:] != shape[1:] or c > shape[0]:
            raise SystemExit(f"--init: {key} has shape {tuple(old.shape)}, cannot widen to {tuple(shape)}")
        new = torch.zeros(shape, dtype=old.dtype)
        new[:c] = old
        if key.endswith("weight"):
            new[c:] = torch.randn((shape[0] - c, *shape[1:]), generator=g) * 0.01
        out[key] = new
    return out


def init_history(path, meta):
    """What the export records about a fine-tuning run's starting weights (metadata ``training.init``)."""
    with open(path, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    keep = ("training.steps", "training.data_seeds", "training.val_seeds", "training.recipe", "training.date")
    history = {"file": os.path.basename(path), "sha256": digest}
    for k in keep:
        if k in meta:
            try:
                history[k.removeprefix("training.")] = json.loads(meta[k])
            except json.JSONDecodeError:  # a date, or a value written as plain text
                history[k.removeprefix("training.")] = meta[k]
    return history


def export(run_dir, cfg, model, step, metrics, train_seeds, val_seeds, device_name):
    """Writes RUN_DIR/<net>.safetensors (the documented format; floats as cfg["export_dtype"])."""
    net = cfg["net"]
    path = os.path.join(run_dir, f"{net}.safetensors")
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    when = (datetime.datetime.fromtimestamp(int(epoch), datetime.timezone.utc) if epoch
            else datetime.datetime.now(datetime.timezone.utc))
    recipe = {k: cfg[k] for k in ("seed", "batch", "lr", "adam_betas", "stages", "flip", "loss_weights")}
    for k in ("augment", "amp", "device_data"):  # what changes the samples or the arithmetic, when used
        if cfg.get(k):
            recipe[k] = cfg[k]
    steps_before = 0
    extra = {}
    history = cfg.get("init_history")
    if history:
        # A fine-tuned file's seeds are those of its whole history, so that evaluate.py still refuses test
        # data any stage of it saw; its steps are the starting file's plus this run's.
        steps_before = int(history.get("steps", 0))
        train_seeds = sorted(set(train_seeds) | set(history.get("data_seeds", [])))
        val_seeds = sorted(set(val_seeds) | set(history.get("val_seeds", [])))
        extra["training.init"] = json.dumps(history, separators=(",", ":"))
    meta = {
        "created_by": "training/train.py",
        "training.date": when.strftime("%Y-%m-%dT%H:%M:%SZ"),
        "training.steps": str(steps_before + step),
        "training.data_seeds": json.dumps(train_seeds),
        "training.val_seeds": json.dumps(val_seeds),
        "training.recipe": json.dumps(recipe, separators=(",", ":")),
        "training.metrics": json.dumps({k: round(v, 6) for k, v in metrics.items()}, separators=(",", ":")),
        "training.loss": "L1 in tanh space on encoded targets (training/synth_data.py)",
        "training.device": device_name,
        "training.torch": torch.__version__,
        **extra,
    }
    model = copy.deepcopy(model).cpu().eval()
    save_weights(model, net, cfg["label"], cfg["model"], path, dtype=DTYPES[cfg["export_dtype"]],
                 extra_metadata=meta)
    return path


def main(argv=None):
    args = arg_parser().parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, flush=True))
    run_dir = args.out
    ckpt_path = os.path.join(run_dir, "checkpoints", "last.pt")
    ckpt = None
    if args.resume or args.export_only:
        if not os.path.exists(ckpt_path):
            raise SystemExit(f"{ckpt_path}: no checkpoint to resume from")
        ckpt = torch.load(ckpt_path, map_location="cpu", weights_only=False)
        cfg = effective_config(args, base=ckpt["config"])
    else:
        if os.path.exists(ckpt_path):
            raise SystemExit(f"{run_dir} already holds a run; use --resume or another --out")
        cfg = effective_config(args)
    net = cfg["net"]
    device = torch.device(args.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    if device.type == "cpu":
        torch.use_deterministic_algorithms(True)
    else:
        torch.backends.cudnn.benchmark = True
    device_name = torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu"

    val_scenes = sd.list_scenes(cfg["val"])[:cfg["val_scenes"]] if cfg["val"] else []
    val_seeds = sd.seeds_of(val_scenes)
    if cfg["device_data"]:
        train_scenes = None
        # The data read so far (a stage's data are read when it begins; the checkpoint says how far).
        read = ckpt.get("data_stage", 0) if ckpt is not None else 0
        train_seeds = disjoint_seeds(sources_until(cfg, read), val_seeds)
    else:
        train_scenes = sd.list_scenes(cfg["data"])
        try:
            sd.check_disjoint({"train": train_scenes, "val": val_scenes})
        except ValueError as e:
            raise SystemExit(str(e)) from None
        train_seeds = sd.seeds_of(train_scenes)
    sample_scenes = (val_scenes or train_scenes or [])[:cfg["sample_scenes"]]
    elements = elements_of(net, cfg["model"])
    steps_known = all("steps" in s for s in cfg["stages"])
    total_steps = sum(s["steps"] for s in cfg["stages"]) if steps_known else None

    seed_everything(cfg["seed"])
    model = build(net, cfg["model"]).to(device)
    nhwc = cfg["channels_last"] and device.type == "cuda"
    if nhwc:
        model = model.to(memory_format=torch.channels_last)
    opt = torch.optim.Adam(model.parameters(), lr=cfg["lr"], betas=tuple(cfg["adam_betas"]))
    step, elapsed, metrics = 0, 0.0, {}
    if cfg.get("init") and ckpt is None:
        state, init_meta = read_init(cfg["init"], net, cfg["model"])
        cfg["init_history"] = init_history(cfg["init"], init_meta)
        mine = model.state_dict()
        missing, extra_keys = sorted(set(mine) - set(state)), sorted(set(state) - set(mine))
        if missing or extra_keys:
            raise SystemExit(f"--init {cfg['init']}: missing tensors {missing}, unexpected {extra_keys}")
        if json.loads(init_meta["config"]) != cfg["model"]:  # read_init allowed it: widen the output
            state = widen_output(state, mine, cfg["seed"])
            say(f"widened {cfg['init']}'s output to {cfg['model']['out_channels']} channels")
        bad = [k for k in mine if tuple(mine[k].shape) != tuple(state[k].shape)]
        if bad:
            raise SystemExit(f"--init {cfg['init']}: misshaped tensors {bad}")
        model.load_state_dict(state)
        say(f"started from {cfg['init']}")
    if cfg.get("init") and not cfg.get("init_history"):
        # A checkpoint written before the history was recorded at the start: read it now.
        _, init_meta = read_init(cfg["init"], net, cfg["model"])
        cfg["init_history"] = init_history(cfg["init"], init_meta)
    if ckpt is not None:
        model.load_state_dict(ckpt["model"])
        opt.load_state_dict(ckpt["optimizer"])
        for g in opt.param_groups:
            g["lr"] = cfg["lr"]
        step, elapsed, metrics = ckpt["step"], ckpt["seconds"], ckpt.get("metrics", {})
        set_rng_state(ckpt["rng"])
    if args.export_only:
        path = export(run_dir, cfg, model, step, metrics, train_seeds, val_seeds, ckpt.get("device", "?"))
        say(f"wrote {path}")
        return path

    os.makedirs(os.path.join(run_dir, "checkpoints"), exist_ok=True)
    os.makedirs(os.path.join(run_dir, "samples"), exist_ok=True)
    with open(os.path.join(run_dir, "config.json"), "w") as f:
        json.dump(cfg, f, indent=2)
        f.write("\n")
    resume_step = step if ckpt is not None else None
    fields = ["step", "stage", "height", "width", "lr", "loss"] + elements + ["seconds"]
    train_log = CsvLog(os.path.join(run_dir, "train.csv"), fields, resume_step)
    val_log = CsvLog(os.path.join(run_dir, "val.csv"), ["step", "loss"] + elements + ["seconds"], resume_step)

    def checkpoint():
        atomic_save({"model": model.state_dict(), "optimizer": opt.state_dict(), "step": step,
                     "seconds": elapsed, "rng": rng_state(), "config": cfg, "metrics": metrics,
                     "device": device_name, "schedule": sched.state(), "data_stage": loaded}, ckpt_path)

    def validate(size):
        nonlocal metrics
        if not val_scenes:
            return
        metrics = evaluate_val(net, model, val_scenes, size, elements, cfg["loss_weights"], cfg["batch"], device)
        val_log.write({"step": step, **{k: fmt(v) for k, v in metrics.items()}, "seconds": fmt(elapsed)})
        say(f"step {step} val loss {metrics['loss']:.4f}")

    batch = cfg["batch"]
    sched = Schedule(cfg["stages"], ckpt.get("schedule") if ckpt is not None else None)
    loaded = 0  # device data: the last stage whose data are read
    if cfg["device_data"]:
        t_load = time.perf_counter()
        loaded = sched.idx if sched.idx < len(cfg["stages"]) else len(cfg["stages"]) - 1
        first = sources_until(cfg, loaded)
        wait_for(first, cfg["data_wait_s"], say)
        train_seeds = disjoint_seeds(first, val_seeds)
        try:
            data = device_data.DeviceData(first, net, cfg["seed"], device, flip=cfg["flip"])
        except (ValueError, FileNotFoundError) as e:
            raise SystemExit(f"--data: {e}") from None
        n_train = len(data)
        say(f"loaded {n_train} scenes onto {device_name} in {time.perf_counter() - t_load:.1f} s")
        check = data.eligible
    else:
        ds = sd.SynthDataset(train_scenes, net, cfg["seed"], StageSize(cfg["stages"], batch), flip=cfg["flip"],
                             cache=cfg["cache"])
        n_train = len(train_scenes)
        check = ds.eligible

    def check_stages(first, last):
        for st in cfg["stages"][first:last]:  # every stage needs scenes at least its size: fail early
            try:
                check(st["size"])
            except ValueError as e:
                raise SystemExit(f"stage {st['size'][0]}x{st['size'][1]}: {e}") from None

    def data_until(stage):  # the stages whose data are all read once stage `stage` has begun
        later = [i for i, st in enumerate(cfg["stages"]) if i > stage and st.get("data")]
        return later[0] if later else len(cfg["stages"])

    if cfg["device_data"]:
        check_stages(0, data_until(loaded))
    else:
        check_stages(0, len(cfg["stages"]))
    paused = [0.0]  # seconds the data source spent reading stage data: not training time
    if cfg["device_data"]:
        def batches():
            nonlocal loaded, train_seeds
            while not (args.until and step >= args.until):
                cur = sched.current(step)
                if cur is None:
                    return
                if cur[0] > loaded:
                    t_read = time.perf_counter()
                    more = [f for st in cfg["stages"][loaded + 1:cur[0] + 1] for f in st.get("data", [])]
                    if not wait_for(more, cfg["data_wait_s"], say, lambda: bool(stop_signal)):
                        return  # stopped by a signal while waiting
                    train_seeds = disjoint_seeds(sources_until(cfg, cur[0]), val_seeds)
                    try:
                        data.add(more)
                    except (ValueError, FileNotFoundError) as e:
                        raise SystemExit(f"stage {cur[0]} data: {e}") from None
                    check_stages(loaded + 1, data_until(cur[0]))
                    loaded = cur[0]
                    paused[0] += time.perf_counter() - t_read
                    say(f"stage {cur[0]}: {len(data)} training scenes (read {more} in "
                        f"{time.perf_counter() - t_read:.1f} s)")
                yield data.batch(range(step * batch, (step + 1) * batch), cur[1])
        source = batches()
        stop = args.until
    else:
        stop = min(total_steps, args.until) if args.until else total_steps
        source = torch.utils.data.DataLoader(
            ds, batch_size=batch, sampler=sd.RangeSampler(step * batch, stop * batch), num_workers=cfg["workers"],
            pin_memory=device.type == "cuda", persistent_workers=False)
    say(f"{net} ({cfg['label']}) on {device_name}: {n_train} training scenes (seeds {train_seeds}), "
        f"{len(val_scenes)} validation; from step {step}, stages {cfg['stages']}")
    model.train()
    use_amp = cfg["amp"] and device.type == "cuda"
    t0 = time.perf_counter()
    total_t, per_t = None, {}
    last_val = last_sample = None
    size = None

    def floats():
        return float(total_t.detach()), {k: float(v.detach()) for k, v in per_t.items()}

    stop_signal = []
    previous = {sig: signal.signal(sig, lambda signum, frame: stop_signal.append(signum))
                for sig in (signal.SIGINT, signal.SIGTERM)}
    for b in source:
        stage, size = sched.current(step)
        lr = stage_lr(cfg, stage)
        for g in opt.param_groups:
            g["lr"] = lr
        b = to_device(b, device)
        if cfg["augment"]:
            b["input"] = device_data.augment_photometric(b["input"], cfg["seed"], step, cfg["augment"])
        if nhwc:
            b["input"] = b["input"].contiguous(memory_format=torch.channels_last)
        with torch.autocast(device_type="cuda", dtype=torch.bfloat16, enabled=use_amp):
            total_t, per_t, _ = losses(net, model, b, elements, cfg["loss_weights"])
        opt.zero_grad(set_to_none=True)
        total_t.backward()
        opt.step()
        step += 1
        if device.type == "cuda" and "steps" not in cfg["stages"][stage] and step % 10 == 0:
            torch.cuda.synchronize(device)  # a stage of seconds counts finished work (within 10 steps)
        now = time.perf_counter()
        dt = now - t0 - paused[0]
        paused[0] = 0.0
        elapsed += dt
        sched.add_time(dt)
        t0 = now
        if step % cfg["log_every"] == 0 or step == 1 or step == stop:
            total_f, per_f = floats()
            row = {"step": step, "stage": stage, "height": size[0], "width": size[1], "lr": lr,
                   "loss": fmt(total_f), "seconds": fmt(elapsed)}
            row.update({k: fmt(v) for k, v in per_f.items()})
            train_log.write(row)
            say(f"step {step}/{total_steps or '?'} {size[0]}x{size[1]} loss {total_f:.4f} ({elapsed:.1f} s)")
        if (step % cfg["sample_every"] == 0 or step == stop) and sample_scenes:
            save_samples(os.path.join(run_dir, "samples", f"step_{step:07d}.png"), net, model, sample_scenes,
                         size, elements, device)
            last_sample = step
        if step % cfg["val_every"] == 0:
            validate(size)
            last_val = step
        if step % cfg["ckpt_every"] == 0 or step == stop:
            checkpoint()
        if stop_signal:
            break
        t0 = time.perf_counter()  # evaluation, pictures and checkpoints are not training time
    for sig, handler in previous.items():
        signal.signal(sig, handler)
    if stop_signal:
        checkpoint()
    if stop_signal or sched.current(step) is not None:
        why = f"signal {stop_signal[0]}" if stop_signal else "--until"
        say(f"stopped at step {step} ({why}); continue with --resume --out {run_dir}, "
            f"or export this state with --export-only --out {run_dir}")
        return None
    if size is None:
        size = tuple(cfg["stages"][-1]["size"])
    if last_val != step:
        validate(size)
    if sample_scenes and last_sample != step:
        save_samples(os.path.join(run_dir, "samples", f"step_{step:07d}.png"), net, model, sample_scenes,
                     size, elements, device)
    checkpoint()
    if not metrics and total_t is not None:  # no validation data: record the last training losses
        total_f, per_f = floats()
        metrics = {f"train_{k}": v for k, v in [("loss", total_f)] + list(per_f.items())}
    path = export(run_dir, cfg, model, step, metrics, train_seeds, val_seeds, device_name)
    say(f"wrote {path}")
    return path

if __name__ == "__main__":
    main()
