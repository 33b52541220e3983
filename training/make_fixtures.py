"""Writes the parity fixtures of fixtures/parity/: tiny-preset weights plus reference inputs and outputs.

Run from the repository root (about 2 s; the output is byte-identical on every run)::

    /tmp/venv/bin/python -m training.make_fixtures [--out fixtures/parity] [--only NAME ...]

(``--only inpaint_tiny`` writes just that fixture; every fixture has its own seeds, so the others' bytes do
not depend on which are written.)

For each fixture ``<name>`` it writes

* ``<name>.safetensors``: weights of the ``tiny`` preset (contract metadata, plus ``created_by`` and
  ``seed``), random but well-conditioned (see :func:`init_weights`, :func:`calibrate_tanh_outputs`);
* ``<name>_io.safetensors`` (F32): ``input`` with outputs ``out.<output name>`` and intermediate
  activations ``act.<module path>``; ``input_odd`` with ``out_odd.<output name>`` run through
  :func:`forward_any`; for some nets ``input_small`` (pads larger than the image: periodic mirror, n = 1)
  and, for EnvMap, ``input_large`` (a tail output larger than 1×1, so the bilinear resize interpolates).
  Inpaint inputs are :func:`inpaint_image`: a smooth texture with a random blobby hole mask, in the layout of
  :func:`training.conventions.inpaint_input`.

References are computed in eval mode in float64 from the exact stored weight values (F16/BF16 weights are
upcast), on one thread, then rounded to float32.
"""

import argparse
import math
import os
from dataclasses import dataclass, field

import numpy as np
import torch
from safetensors.torch import load_file
from torch import nn

from training.conventions import inpaint_input
from training.picker_nets import (
    Decoder,
    ResBlock,
    build,
    forward_any,
    named_outputs,
    preset,
    save_safetensors,
    save_weights,
)

CREATED_BY = "training/make_fixtures.py"
TANH_INPUT_RMS = 0.6
"""Target RMS of the pre-tanh activations after calibration: outputs mostly in (-0.9, 0.9)."""


@dataclass
class Fixture:
    """One weights file and its reference io file."""

    name: str
    net: str
    seed: int
    dtype: torch.dtype
    input_shape: tuple
    odd_shape: tuple
    acts: tuple
    extra_inputs: dict = field(default_factory=dict)  # suffix → shape, run through forward_any
    config: dict = field(default_factory=dict)  # changes to the tiny preset (the weights' preset is then "custom")


IRN_ACTS = ("enc", "heads.normals.blocks.0", "heads.normals.dec.up.0")
MSN_ACTS = ("enc", "blocks.1")
ENVMAP_ACTS = ("enc", "blocks.0", "tail.1")
INPAINT_ACTS = ("enc.conv_in", "enc", "blocks.1", "dec.up.1")

FIXTURES = (
    Fixture("irn_tiny", "irn", 1, torch.float32, (1, 3, 24, 32), (1, 3, 21, 27), IRN_ACTS),
    Fixture("msn_tiny", "msn", 2, torch.float32, (2, 3, 20, 28), (1, 3, 21, 27), MSN_ACTS,
            {"small": (1, 3, 2, 3)}),
    Fixture("envmap_tiny", "envmap", 3, torch.float32, (1, 3, 40, 56), (1, 3, 13, 30), ENVMAP_ACTS,
            {"small": (1, 3, 1, 5), "large": (1, 3, 72, 136)}),
    Fixture("msn_tiny_f16", "msn", 4, torch.float16, (2, 3, 20, 28), (1, 3, 21, 27), MSN_ACTS),
    Fixture("envmap_tiny_bf16", "envmap", 6, torch.bfloat16, (1, 3, 40, 56), (1, 3, 13, 30), ENVMAP_ACTS,
            {"large": (1, 3, 72, 136)}),
    Fixture("msn_tiny_embed", "msn", 8, torch.float32, (1, 3, 20, 28), (1, 3, 21, 27), MSN_ACTS,
            config={"out_channels": 6}),
    Fixture("inpaint_tiny", "inpaint", 7, torch.float32, (2, 4, 20, 28), (1, 4, 21, 27), INPAINT_ACTS,
            {"small": (1, 4, 2, 3)}),
)


def smooth_image(rng, shape):
    """A smooth-ish test image in [-1, 1]: per channel a sum of 4 random sinusoids plus small noise."""
    n, c, h, w = shape
    yy, xx = np.meshgrid(np.arange(h) / h, np.arange(w) / w, indexing="ij")
    img = np.zeros(shape)
    for i in range(n):
        for ch in range(c):
            for _ in range(4):
                fy, fx = rng.uniform(-3, 3, size=2)
                amplitude, phase = rng.uniform(0.2, 0.5), rng.uniform(0, 2 * np.pi)
                img[i, ch] += amplitude * np.sin(2 * np.pi * (fy * yy + fx * xx) + phase)
    img += rng.normal(0, 0.05, size=shape)
    return torch.from_numpy(np.clip(img, -1, 1).astype(np.float32))


def inpaint_image(rng, shape):
    """An inpainter input [N, C + 1, H, W]: a :func:`smooth_image` texture (as sRGB (x + 1) / 2) with a
    random hole mask per image (a smooth random field thresholded so that about 60% is known, at least one
    texel known and one unknown), through :func:`training.conventions.inpaint_input`."""
    n, c, h, w = shape
    texture = (smooth_image(rng, (n, c - 1, h, w)) + 1) / 2
    items = []
    for i in range(n):
        field = smooth_image(rng, (1, 1, h, w))[0, 0]
        known = field > torch.quantile(field.flatten(), 0.4)
        known.view(-1)[0], known.view(-1)[-1] = True, False
        items.append(inpaint_input(texture[i:i + 1], known))
    return torch.cat(items)


def test_input(rng, net, shape):
    """The reference input of ``net``: :func:`smooth_image`, or :func:`inpaint_image` for the inpainter."""
    return inpaint_image(rng, shape) if net == "inpaint" else smooth_image(rng, shape)


def init_weights(model):
    """Random, well-conditioned parameters and BatchNorm statistics (global torch RNG, module order).

    Conv weights He-normal, std sqrt(2 / fan_in) (fan_in = c_in·k² for convs, c_in·k²/stride² for the
    stride-2 transposed convs, which is how many inputs reach each output); the second conv of each
    ResBlock ×0.2; conv biases N(0, 0.1); BN gamma U(0.5, 1.5), beta N(0, 0.2), running_mean N(0, 0.3),
    running_var U(0.5, 2), num_batches_tracked a random positive int.
    """
    with torch.no_grad():
        for m in model.modules():
            if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d)):
                k, s = m.kernel_size[0], m.stride[0]
                fan_in = m.in_channels * k * k / (s * s if isinstance(m, nn.ConvTranspose2d) else 1)
                m.weight.normal_(0.0, math.sqrt(2.0 / fan_in))
                if m.bias is not None:
                    m.bias.normal_(0.0, 0.1)
            elif isinstance(m, nn.BatchNorm2d):
                m.weight.uniform_(0.5, 1.5)
                m.bias.normal_(0.0, 0.2)
                m.running_mean.normal_(0.0, 0.3)
                m.running_var.uniform_(0.5, 2.0)
                m.num_batches_tracked.fill_(int(torch.randint(1, 10_000, ())))
        for m in model.modules():
            if isinstance(m, ResBlock):
                m.conv2.weight.mul_(0.2)


def pre_tanh_layers(model):
    """(module whose output is a pre-tanh activation, tensors that scale that output linearly).

    Decoders: ``conv_out`` (weight and bias); EnvMap: the BN of ``tail.2`` (gamma and beta).
    """
    if model.net == "envmap":
        bn = model.tail[2].bn
        return [(bn, (bn.weight, bn.bias))]
    decoders = [m for m in model.modules() if isinstance(m, Decoder)]
    return [(d.conv_out, (d.conv_out.weight, d.conv_out.bias)) for d in decoders]


def calibrate_tanh_outputs(model, inputs):
    """Scales each tanh layer so its pre-tanh activations have RMS ``TANH_INPUT_RMS`` over ``inputs``.

    ``model`` must be in float64 eval mode; the inputs go through :func:`forward_any`.
    """
    layers = pre_tanh_layers(model)
    seen = {id(m): [] for m, _ in layers}
    hooks = [m.register_forward_hook(lambda mod, _i, out: seen[id(mod)].append(out.flatten()))
             for m, _ in layers]
    with torch.no_grad():
        for x in inputs:
            forward_any(model, x.double())
        for h in hooks:
            h.remove()
        for m, tensors in layers:
            scale = TANH_INPUT_RMS / torch.cat(seen[id(m)]).square().mean().sqrt()
            for t in tensors:
                t.mul_(scale)


def stored_state(path):
    """The state dict exactly as stored in ``path``, floating tensors upcast to float64."""
    return {k: v.double() if v.is_floating_point() else v for k, v in load_file(path).items()}


def reference(model, x, act_paths=()):
    """Outputs {name: tensor} and activations {path: tensor} of ``forward_any(model, x)`` as float32.

    ``model`` is in float64 eval mode; activations are the outputs of the named submodules.
    """
    acts = {}
    hooks = [model.get_submodule(p).register_forward_hook(lambda _m, _i, out, p=p: acts.__setitem__(p, out))
             for p in act_paths]
    with torch.no_grad():
        out = forward_any(model, x.double())
    for h in hooks:
        h.remove()
    outs = named_outputs(model.net, out)
    return {k: v.float() for k, v in outs.items()}, {p: acts[p].float() for p in act_paths}


def make_fixture(fx, out_dir):
    """Writes ``<name>.safetensors`` and ``<name>_io.safetensors``; returns the io tensors."""
    torch.manual_seed(fx.seed)
    rng = np.random.default_rng(fx.seed)
    config = {**preset(fx.net, "tiny"), **fx.config}
    label = "custom" if fx.config else "tiny"
    model = build(fx.net, config)
    init_weights(model)
    inputs = {"": test_input(rng, fx.net, fx.input_shape), "_odd": test_input(rng, fx.net, fx.odd_shape)}
    inputs.update({f"_{k}": test_input(rng, fx.net, shape) for k, shape in fx.extra_inputs.items()})
    model.double().eval()
    calibrate_tanh_outputs(model, inputs.values())

    weights = os.path.join(out_dir, f"{fx.name}.safetensors")
    meta = {"created_by": CREATED_BY, "seed": str(fx.seed)}
    save_weights(model, fx.net, label, config, weights, dtype=fx.dtype, extra_metadata=meta)
    model.load_state_dict(stored_state(weights))  # the reference runs on the stored (rounded) values

    io = {}
    for suffix, x in inputs.items():
        outs, acts = reference(model, x, fx.acts if suffix == "" else ())
        io[f"input{suffix}"] = x
        io.update({f"out{suffix}.{k}": v for k, v in outs.items()})
        io.update({f"act.{k}": v for k, v in acts.items()})
    io_meta = {**meta, "net": fx.net, "weights": os.path.basename(weights),
               "reference": "float64 eval of the stored weights, forward_any, rounded to float32"}
    io_path = os.path.join(out_dir, f"{fx.name}_io.safetensors")
    save_safetensors({k: v.contiguous() for k, v in io.items()}, io_path, io_meta)
    return io


def check_conditioning(name, io):
    """Prints output statistics; fails unless every output is finite, unsaturated (max |y| < 0.999, at
    least 90% of |y| < 0.9) and not near zero (std > 0.1)."""
    for k, v in io.items():
        if not k.startswith("out"):
            continue
        inside = (v.abs() < 0.9).double().mean()
        print(f"  {k:32s} {tuple(v.shape)!s:18s} max|y| {v.abs().max():.3f}  std {v.std():.3f}  "
              f"|y|<0.9 {inside:.3f}")
        if not torch.isfinite(v).all() or v.abs().max() >= 0.999 or inside < 0.9 or v.std() <= 0.1:
            raise RuntimeError(f"{name}: {k} is badly conditioned; choose another seed")


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(root, "fixtures", "parity"), help="output folder")
    ap.add_argument("--only", nargs="+", metavar="NAME", choices=[fx.name for fx in FIXTURES],
                    help="write only these fixtures (default: all)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    torch.set_num_threads(1)  # one summation order, whatever the machine
    for fx in FIXTURES:
        if args.only and fx.name not in args.only:
            continue
        print(f"{fx.name} ({fx.net}, seed {fx.seed}, {str(fx.dtype).removeprefix('torch.')})")
        check_conditioning(fx.name, make_fixture(fx, args.out))


if __name__ == "__main__":
    main()
