"""IRN, MSN, EnvMap and the learned inpainter as PyTorch modules: the reference the Rust crate `picker-nets` is tested against.

Everything here follows docs/contract.md to the letter: the modules are built from the contract's config
dicts (see :mod:`training.presets`), ``model.state_dict()`` keys are exactly the contract's keys, and
:func:`save_weights` writes the contract's safetensors metadata, so exporting weights is one ``save_file``.

Self-test (thesis parameter counts, key names, tiny forward passes, any-size padding)::

    /tmp/venv/bin/python -m training.test_picker_nets
"""

import json
import os
import struct

import torch
import torch.nn.functional as F
from safetensors.torch import save_file
from torch import nn

from training.presets import (  # noqa: F401  (preset and count_params_folded are re-exported)
    NETS,
    config_json,
    count_params_folded,
    in_channels,
    preset,
    validate_config,
)

FORMAT = "material-picker"
FORMAT_VERSION = "1"


def _activate(x, act):
    if act == "relu":
        return torch.relu(x)
    if act == "tanh":
        return torch.tanh(x)
    raise ValueError(f"unknown activation {act!r}")


def _reflect(x, p):
    """ReflectionPad(p) of the contract (inside the nets the size always exceeds p)."""
    return F.pad(x, (p, p, p, p), mode="reflect")


class ConvBn(nn.Module):
    """``conv`` (Conv2d, zero padding) → ``bn`` (BatchNorm2d) → activation (``relu`` or ``tanh``)."""

    def __init__(self, cin, cout, k, stride, pad, bias, eps, act="relu"):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, k, stride=stride, padding=pad, bias=bias)
        self.bn = nn.BatchNorm2d(cout, eps=eps)
        self.act = act

    def forward(self, x):
        return _activate(self.bn(self.conv(x)), self.act)


class ConvTBn(nn.Module):
    """``conv`` (ConvTranspose2d 3×3, stride 2, padding 1, output_padding 1: ×2 spatially) → ``bn`` → ReLU."""

    def __init__(self, cin, cout, bias, eps):
        super().__init__()
        self.conv = nn.ConvTranspose2d(cin, cout, 3, stride=2, padding=1, output_padding=1, bias=bias)
        self.bn = nn.BatchNorm2d(cout, eps=eps)

    def forward(self, x):
        return torch.relu(self.bn(self.conv(x)))


class ResBlock(nn.Module):
    """x + BN(Conv3(pad(ReLU(BN(Conv3(pad(x))))))), reflection padding 1, no activation after the sum."""

    def __init__(self, c, bias, eps):
        super().__init__()
        self.conv1 = nn.Conv2d(c, c, 3, bias=bias)
        self.bn1 = nn.BatchNorm2d(c, eps=eps)
        self.conv2 = nn.Conv2d(c, c, 3, bias=bias)
        self.bn2 = nn.BatchNorm2d(c, eps=eps)

    def forward(self, x):
        h = torch.relu(self.bn1(self.conv1(_reflect(x, 1))))
        return x + self.bn2(self.conv2(_reflect(h, 1)))


class Encoder(nn.Module):
    """ReflectionPad(3) → ``conv_in`` 7×7 (stride ``stride0``, ``cin`` inputs) → ``down.0``, ``down.1``
    3×3 stride 2."""

    def __init__(self, widths, stride0, bias, eps, cin=3):
        super().__init__()
        w0, w1, w2 = widths
        self.conv_in = ConvBn(cin, w0, 7, stride0, 0, bias, eps)
        self.down = nn.ModuleList([ConvBn(w0, w1, 3, 2, 1, bias, eps), ConvBn(w1, w2, 3, 2, 1, bias, eps)])

    def forward(self, x):
        x = self.conv_in(_reflect(x, 3))
        for layer in self.down:
            x = layer(x)
        return x


class Decoder(nn.Module):
    """``up.0``, ``up.1`` (ConvTBn, ×4 spatially) → ReflectionPad(3) → ``conv_out`` 7×7 with bias → Tanh."""

    def __init__(self, widths, channels, bias, eps):
        super().__init__()
        w0, w1, w2 = widths
        self.up = nn.ModuleList([ConvTBn(w2, w1, bias, eps), ConvTBn(w1, w0, bias, eps)])
        self.conv_out = nn.Conv2d(w0, channels, 7, bias=True)

    def forward(self, x):
        for layer in self.up:
            x = layer(x)
        return torch.tanh(self.conv_out(_reflect(x, 3)))


def _blocks(config):
    w2 = config["widths"][2]
    return nn.ModuleList(
        [ResBlock(w2, config["conv_bias"], config["bn_eps"]) for _ in range(config["blocks"])])


def _run(blocks, x):
    for block in blocks:
        x = block(x)
    return x


class IrnHead(nn.Module):
    """One IRN head: ``blocks.<i>`` ResBlocks, then ``dec`` Decoder(channels)."""

    def __init__(self, config, channels):
        super().__init__()
        self.blocks = _blocks(config)
        self.dec = Decoder(config["widths"], channels, config["conv_bias"], config["bn_eps"])

    def forward(self, x):
        return self.dec(_run(self.blocks, x))


class Irn(nn.Module):
    """Intrinsic rendering network: shared ``enc`` (stride 1), one ``heads.<name>`` per head.

    ``forward`` returns a dict head name → tanh tensor [N, channels, H, W] (H, W multiples of 4).
    """

    net = "irn"

    def __init__(self, config):
        super().__init__()
        validate_config(self.net, config)
        self.config = config
        self.enc = Encoder(config["widths"], 1, config["conv_bias"], config["bn_eps"])
        self.heads = nn.ModuleDict({h["name"]: IrnHead(config, h["channels"]) for h in config["heads"]})

    def forward(self, x):
        features = self.enc(x)
        return {name: head(features) for name, head in self.heads.items()}


class Msn(nn.Module):
    """Material segmentation network: ``enc`` (stride 1) → ``blocks.<i>`` → ``dec``; returns the tanh map."""

    net = "msn"

    def __init__(self, config):
        super().__init__()
        validate_config(self.net, config)
        self.config = config
        self.enc = Encoder(config["widths"], 1, config["conv_bias"], config["bn_eps"])
        self.blocks = _blocks(config)
        self.dec = Decoder(config["widths"], config["out_channels"], config["conv_bias"], config["bn_eps"])

    def forward(self, x):
        return self.dec(_run(self.blocks, self.enc(x)))


class EnvMap(nn.Module):
    """Environment-map network: ``enc`` (stride 2) → ``blocks.<i>`` → ``tail.0..2`` (stride 2 each, the last
    with Tanh) → bilinear resize (align_corners=False).

    ``forward(x, out_size=None)``: the output is resized to ``out_size`` (rows, cols), by default
    (max(1, H//8), max(1, W//8)) of ``x``; :func:`forward_any` passes the size of the unpadded image.
    """

    net = "envmap"

    def __init__(self, config):
        super().__init__()
        validate_config(self.net, config)
        self.config = config
        bias, eps = config["conv_bias"], config["bn_eps"]
        t0, t1 = config["tail_widths"]
        self.enc = Encoder(config["widths"], 2, bias, eps)
        self.blocks = _blocks(config)
        self.tail = nn.ModuleList([
            ConvBn(config["widths"][2], t0, 1, 2, 0, bias, eps),
            ConvBn(t0, t1, 3, 2, 1, bias, eps),
            ConvBn(t1, config["out_channels"], 3, 2, 1, bias, eps, act="tanh"),
        ])

    def forward(self, x, out_size=None):
        if out_size is None:
            out_size = envmap_size(*x.shape[-2:])
        y = _run(self.tail, _run(self.blocks, self.enc(x)))
        return F.interpolate(y, size=out_size, mode="bilinear", align_corners=False)


class Inpaint(nn.Module):
    """Learned texture inpainter (pix2pix ResnetGenerator-style, the MSN's structure): ``enc`` (stride 1,
    ``channels + 1`` inputs) → ``blocks.<i>`` → ``dec`` (``channels`` tanh outputs).

    Input (:func:`training.conventions.inpaint_input`): planes ``0..channels`` = 2·srgb − 1 at known texels
    and 0 at unknown ones, plane ``channels`` = +1 known / −1 unknown. Output: the whole texture in [-1, 1]
    (sRGB (y + 1) / 2); callers keep their known texels.
    """

    net = "inpaint"

    def __init__(self, config):
        super().__init__()
        validate_config(self.net, config)
        self.config = config
        bias, eps = config["conv_bias"], config["bn_eps"]
        self.enc = Encoder(config["widths"], 1, bias, eps, cin=in_channels(self.net, config))
        self.blocks = _blocks(config)
        self.dec = Decoder(config["widths"], config["channels"], bias, eps)

    def forward(self, x):
        return self.dec(_run(self.blocks, self.enc(x)))


MODELS = {"irn": Irn, "msn": Msn, "envmap": EnvMap, "inpaint": Inpaint}


def build(net, config):
    """The model for ``net`` (``irn`` | ``msn`` | ``envmap`` | ``inpaint``) with fresh parameters."""
    if net not in MODELS:
        raise ValueError(f"unknown net {net!r}; expected one of {NETS}")
    return MODELS[net](config)


def envmap_size(h, w):
    """Size (rows, cols) of the environment map for an h×w input image: (max(1, h//8), max(1, w//8))."""
    return max(1, h // 8), max(1, w // 8)


def padded_size(net, h, w):
    """Size the contract pads an h×w input to: IRN/MSN/inpaint max(8, ceil4(·)) per axis, EnvMap
    max(16, ·)."""
    if net == "envmap":
        return max(16, h), max(16, w)
    return max(8, -(-h // 4) * 4), max(8, -(-w // 4) * 4)


def mirror_indices(n, before, after):
    """Source indices along an axis of length ``n`` padded by ``before`` and ``after`` elements.

    Mirror extension without repeating the edge sample (…, 2, 1, [0, 1, …, n-1], n-2, …), continued
    periodically with period 2(n−1) when a pad exceeds n−1; n = 1 repeats the single sample.
    """
    idx = torch.arange(-before, n + after)
    if n == 1:
        return torch.zeros_like(idx)
    period = 2 * (n - 1)
    idx = torch.remainder(idx, period)
    return torch.where(idx >= n, period - idx, idx)


def mirror_pad(x, top, bottom, left, right):
    """Pads the last two axes of ``x`` by mirror extension (see :func:`mirror_indices`)."""
    h, w = x.shape[-2:]
    x = x.index_select(-2, mirror_indices(h, top, bottom).to(x.device))
    return x.index_select(-1, mirror_indices(w, left, right).to(x.device))


def forward_any(model, x):
    """Runs ``model`` on an input of any size [N, C, H, W] (C = 3; inpaint: channels + 1), following the
    contract's padding policy.

    The input is mirror-padded to :func:`padded_size` (top = (Hp−H)//2, bottom = the rest, likewise left and
    right). IRN/MSN outputs are cropped back to H×W; the EnvMap output has the size of the unpadded input.
    """
    h, w = x.shape[-2:]
    hp, wp = padded_size(model.net, h, w)
    top, left = (hp - h) // 2, (wp - w) // 2
    xp = mirror_pad(x, top, hp - h - top, left, wp - w - left)
    if model.net == "envmap":
        return model(xp, out_size=envmap_size(h, w))
    out = model(xp)

    def crop(y):
        return y[..., top:top + h, left:left + w]

    return {k: crop(v) for k, v in out.items()} if isinstance(out, dict) else crop(out)


OUTPUT_NAMES = {"msn": "segmentation", "envmap": "envmap", "inpaint": "inpainted"}
"""Names of the single outputs of MSN, EnvMap and the inpainter (IRN outputs are named by head)."""


def named_outputs(net, out):
    """The output of a ``net`` forward pass as a dict output name → tensor. An MSN with more than three
    output channels gives ``segmentation`` (the first three) and ``embedding`` (the rest; see
    :mod:`training.embedding`)."""
    if net == "irn":
        return out
    if net == "msn" and out.shape[1] > 3:
        return {"segmentation": out[:, :3], "embedding": out[:, 3:]}
    return {OUTPUT_NAMES[net]: out}


def conv_modules(model):
    """(name, module) of every Conv2d / ConvTranspose2d of ``model``, in state_dict order."""
    return [(n, m) for n, m in model.named_modules() if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d))]


def save_safetensors(tensors, path, metadata):
    """``safetensors.torch.save_file`` with byte-reproducible output.

    safetensors writes the ``__metadata__`` map in hash order, which changes from process to process; the
    header is rewritten in place with the metadata keys sorted (same JSON length, so offsets are unchanged).
    Written to ``path + ".tmp"`` and renamed, so an interrupted export never leaves a half-written file.
    """
    tmp = os.fspath(path) + ".tmp"
    save_file(tensors, tmp, metadata=metadata)
    if metadata:
        _sort_metadata(tmp)
    os.replace(tmp, path)


def _sort_metadata(path):
    """Rewrites the safetensors header of ``path`` in place with its metadata keys sorted."""
    with open(path, "r+b") as f:
        (n,) = struct.unpack("<Q", f.read(8))
        raw = f.read(n)
        header = json.loads(raw)
        header["__metadata__"] = dict(sorted(header["__metadata__"].items()))
        text = json.dumps(header, separators=(",", ":"), ensure_ascii=False).encode()
        if len(text.rstrip()) != len(raw.rstrip()):
            raise RuntimeError(f"{path}: canonical header length differs from the safetensors header")
        f.seek(8)
        f.write(text.ljust(n))


def save_weights(model, net, preset, config, path, dtype=torch.float32, extra_metadata=None):
    """Saves ``model.state_dict()`` as a weights file of the contract.

    Floating tensors are stored as ``dtype`` (F32, F16 or BF16); ``num_batches_tracked`` stays an int64
    scalar. Metadata: ``format``, ``format_version``, ``net``, ``preset``, ``config`` (compact JSON with
    exactly the contract's keys), plus free-form ``extra_metadata`` (e.g. ``created_by``).
    """
    validate_config(net, config)
    if model.net != net or model.config != config:
        raise ValueError(f"model ({model.net}, {model.config}) does not match ({net}, {config})")
    metadata = {"format": FORMAT, "format_version": FORMAT_VERSION, "net": net, "preset": preset,
                "config": config_json(config)}
    for key, value in (extra_metadata or {}).items():
        if key in metadata:
            raise ValueError(f"metadata key {key!r} is reserved")
        metadata[key] = str(value)
    state = {k: (v.to(dtype) if v.is_floating_point() else v).contiguous()
             for k, v in model.state_dict().items()}
    save_safetensors(state, path, metadata)
