"""Test-split metrics of trained weights against simple baselines (the model card's figures), as JSON.

    python -m training.evaluate --weights runs/irn --weights runs/msn --weights runs/envmap \\
        --data DATA/test --out metrics.json [--size 240x320] [--limit 500]

``--weights`` takes weights files or folders holding ``irn``/``msn``/``envmap.safetensors`` (those present are
evaluated). The test folder's ``picker synth`` seeds must not appear in a file's ``training.data_seeds`` or
``training.val_seeds`` metadata (refused otherwise). Scenes are used whole (``--size`` reduces them as the trainer
does, e.g. 240×320 data at 120×160), without mirroring; the nets run through ``forward_any``.

Metrics (means over scenes of per-scene values; "surface" = pixels that are not sky):

=====================  =======================================================  ===============================
metric                 model                                                    baseline
=====================  =======================================================  ===============================
``albedo_si_mse``      diffuse albedo, scale-invariant MSE on surface pixels:   the image itself (linear RGB)
                       min over one scalar a of mean((a·pred − true)²)          as albedo
``albedo_si_l1``       mean |a·pred − true| with the same a                     same
``normals_deg``        mean angle (degrees) between predicted and true normals  all normals face the camera
                       on surface pixels                                        (0, 0, 1)
``uv_error``           mean wrap-around distance min(|Δ|, 1 − |Δ|) of u and v   constant (0.5, 0.5)
                       on textured pixels
``uv_t_accuracy``      fraction of surface pixels whose t (≥ 0.5: textured) is  "everything textured"
                       right
``envmap_log_l1``      mean |ln(1 + L̂) − ln(1 + L)| over the map               a uniform map of the image's
                                                                                mean linear colour
``segmentation_l1``    mean |ŝ − s| of the decoded segmentation colours         the image's linear colour
=====================  =======================================================  ===============================

``improvement`` = 1 − model / baseline for errors (model / baseline − 1 for accuracies): the issue asks ≥ 0.3
on albedo and normals.
"""

import argparse
import json
import math
import os

import torch
from safetensors import safe_open

from training import synth_data as sd
from training.picker_nets import build, forward_any, named_outputs
from training.train import parse_size


def load_weights(path):
    """(net, model in eval mode, metadata) of a weights file (any float dtype; computed in f32)."""
    with safe_open(path, framework="pt") as f:
        meta = f.metadata() or {}
        state = {k: f.get_tensor(k) for k in f.keys()}
    net = meta["net"]
    model = build(net, json.loads(meta["config"]))
    model.load_state_dict({k: (v.float() if v.is_floating_point() else v) for k, v in state.items()})
    return net, model.eval(), meta


def weight_files(items):
    files = []
    for item in items:
        if os.path.isdir(item):
            found = [os.path.join(item, f"{n}.safetensors") for n in ("irn", "msn", "envmap")]
            found = [f for f in found if os.path.exists(f)]
            if not found:
                raise SystemExit(f"{item}: no irn/msn/envmap.safetensors inside")
            files += found
        else:
            files.append(item)
    return files


def load_all(scene_dir, nets):
    raw = {}
    for net in nets:
        raw.update(sd.load_scene(scene_dir, net))
    return raw


def scene_metrics(sample, outputs):
    """Per-scene metric dict {name: (model, baseline)} from a prepared sample (tanh targets) and decoded
    network outputs (dict element → [3 or 1, H, W] tanh values)."""
    m = {}
    image_lin = sd.srgb_decode(sd.conv.to_unit(sample["input"]).clamp(0, 1))
    surface = sample["surface"][0] > 0.5
    if "diffuse_albedo" in outputs and surface.any():
        true = sd.conv.to_unit(sample["diffuse_albedo"])[:, surface]
        pred = sd.conv.to_unit(outputs["diffuse_albedo"]).clamp(0, 1)[:, surface]
        base = image_lin[:, surface]

        def si(p):
            a = float((p * true).sum() / (p * p).sum().clamp_min(1e-12))
            d = a * p - true
            return float((d * d).mean()), float(d.abs().mean())

        (pm, pl), (bm, bl) = si(pred), si(base)
        m["albedo_si_mse"], m["albedo_si_l1"] = (pm, bm), (pl, bl)
    if "normals" in outputs and surface.any():
        true = sd.conv.unit_vectors(sample["normals"])[:, surface]
        pred = sd.conv.unit_vectors(outputs["normals"])[:, surface]

        def deg(p):
            return float(torch.rad2deg(torch.acos((p * true).sum(0).clamp(-1, 1))).mean())

        m["normals_deg"] = (deg(pred), deg(torch.tensor([0.0, 0.0, 1.0])[:, None].expand_as(true)))
    if "uv" in outputs:
        textured = sample["textured"][0] > 0.5
        true = sd.conv.texture_coords(sample["uv"])
        pred = sd.conv.texture_coords(outputs["uv"])
        if textured.any():
            def wrap_err(p):
                d = (p[:2, textured] - true[:2, textured]).abs()
                return float(torch.minimum(d, 1 - d).mean())

            m["uv_error"] = (wrap_err(pred), wrap_err(torch.full_like(pred, 0.5)))
        if surface.any():
            t_true = true[2, surface] >= 0.5
            acc = float(((pred[2, surface] >= 0.5) == t_true).float().mean())
            m["uv_t_accuracy"] = (acc, float(t_true.float().mean()))
    if "envmap" in outputs:
        true = sd.conv.env_radiance(sample["envmap"])
        pred = sd.conv.env_radiance(outputs["envmap"])
        base = image_lin.mean(dim=(1, 2), keepdim=True).expand_as(true)

        def log_l1(p):
            return float((torch.log1p(p) - torch.log1p(true)).abs().mean())

        m["envmap_log_l1"] = (log_l1(pred), log_l1(base))
    if "segmentation" in outputs:
        true = sd.conv.to_unit(sample["segmentation"])
        pred = sd.conv.to_unit(outputs["segmentation"]).clamp(0, 1)
        m["segmentation_l1"] = (float((pred - true).abs().mean()), float((image_lin - true).abs().mean()))
    return m


HIGHER_IS_BETTER = {"uv_t_accuracy"}


def evaluate(weights, data, size=None, limit=None, allow_overlap=False):
    """The metrics JSON object (see the module docs)."""
    models = {}
    metas = {}
    for path in weight_files(weights):
        net, model, meta = load_weights(path)
        if net not in ("irn", "msn", "envmap"):
            raise SystemExit(f"{path}: {net} weights have no synth metric")
        models[net], metas[net] = model, {"file": path, **meta}
    scenes = sd.list_scenes(data)
    if limit:
        scenes = scenes[:limit]
    test_seeds = sd.seeds_of(scenes)
    for net, meta in metas.items():
        used = set(json.loads(meta.get("training.data_seeds", "[]"))) | set(
            json.loads(meta.get("training.val_seeds", "[]")))
        if used & set(test_seeds) and not allow_overlap:
            raise SystemExit(f"{meta['file']}: trained or validated on seeds {sorted(used & set(test_seeds))} "
                             "of the test data; evaluate on another seed")
    sums, counts = {}, {}
    with torch.no_grad():
        for scene in scenes:
            raw = load_all(scene, models)
            h0, w0 = raw["image"].shape[1:]
            sample = sd.prepare(raw, tuple(size) if size else (h0, w0), None, flip=False, crop="centre")
            x = sample["input"][None]
            outputs = {}
            for net, model in models.items():
                outputs.update({k: v[0] for k, v in named_outputs(net, forward_any(model, x)).items()})
            for name, (mv, bv) in scene_metrics(sample, outputs).items():
                s = sums.setdefault(name, [0.0, 0.0])
                s[0] += mv
                s[1] += bv
                counts[name] = counts.get(name, 0) + 1
    metrics = {}
    for name, (ms, bs) in sums.items():
        mv, bv = ms / counts[name], bs / counts[name]
        if name in HIGHER_IS_BETTER:
            imp = mv / bv - 1 if bv > 0 else math.nan
        else:
            imp = 1 - mv / bv if bv > 0 else math.nan
        metrics[name] = {"model": mv, "baseline": bv, "improvement": imp, "scenes": counts[name]}
    return {"data": [os.fspath(d) for d in data], "scenes": len(scenes), "test_seeds": test_seeds,
            "size": list(size) if size else None, "weights": metas, "metrics": metrics}


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m training.evaluate", description=__doc__.split("\n\n")[0])
    p.add_argument("--weights", action="append", required=True, help="weights file or run folder (repeatable)")
    p.add_argument("--data", action="append", required=True, help="test folder of picker synth scenes")
    p.add_argument("--out", help="write the JSON here (default: print it)")
    p.add_argument("--size", type=parse_size, help="evaluate at HxW (reduced/cropped as in training)")
    p.add_argument("--limit", type=int, help="at most this many scenes")
    p.add_argument("--threads", type=int)
    p.add_argument("--allow-overlap", action="store_true", help="allow test seeds seen in training (smoke tests)")
    args = p.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    result = evaluate(args.weights, args.data, args.size, args.limit, args.allow_overlap)
    text = json.dumps(result, indent=2) + "\n"
    if args.out:
        tmp = args.out + ".tmp"
        with open(tmp, "w") as f:
            f.write(text)
        os.replace(tmp, args.out)  # never a half-written metrics file
    else:
        print(text, end="")
    return result


if __name__ == "__main__":
    main()
