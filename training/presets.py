"""Network configurations of docs/contract.md, without any dependency on torch.

A config is the plain dict stored as JSON in a weights file's ``__metadata__["config"]``. Its keys are
exactly the contract's (unknown or missing keys are an error, as in the Rust loader). This module is
imported both by :mod:`training.picker_nets` and by ``scripts/ort-anchor`` (which has no torch), so the
presets and the parameter count live in one place.
"""

import copy
import json

NETS = ("irn", "msn", "envmap", "inpaint")

IRN_HEADS = (
    ("diffuse_albedo", 3),
    ("specular_albedo", 3),
    ("normals", 3),
    ("glossiness", 1),
    ("view_vector", 3),
    ("uv", 3),
)

CONFIG_KEYS = {
    "irn": ("widths", "blocks", "heads", "conv_bias", "bn_eps"),
    "msn": ("widths", "blocks", "out_channels", "conv_bias", "bn_eps"),
    "envmap": ("widths", "blocks", "tail_widths", "out_channels", "conv_bias", "bn_eps"),
    "inpaint": ("widths", "blocks", "channels", "conv_bias", "bn_eps"),
}


def _heads():
    return [{"name": name, "channels": c} for name, c in IRN_HEADS]


PRESETS = {
    "irn": {
        "thesis": {"widths": [64, 128, 256], "blocks": 15, "heads": _heads(), "conv_bias": False,
                   "bn_eps": 1e-5},
        "lite": {"widths": [16, 32, 64], "blocks": 3, "heads": _heads(), "conv_bias": False, "bn_eps": 1e-5},
        "tiny": {"widths": [8, 12, 16], "blocks": 2, "heads": _heads(), "conv_bias": True, "bn_eps": 1e-5},
    },
    "msn": {
        "thesis": {"widths": [64, 128, 256], "blocks": 9, "out_channels": 3, "conv_bias": False,
                   "bn_eps": 1e-5},
        "lite": {"widths": [24, 48, 96], "blocks": 4, "out_channels": 6, "conv_bias": False, "bn_eps": 1e-5},
        "tiny": {"widths": [8, 12, 16], "blocks": 2, "out_channels": 3, "conv_bias": False, "bn_eps": 1e-5},
    },
    "envmap": {
        "thesis": {"widths": [64, 128, 256], "blocks": 4, "tail_widths": [256, 128], "out_channels": 3,
                   "conv_bias": False, "bn_eps": 1e-5},
        "lite": {"widths": [16, 32, 64], "blocks": 2, "tail_widths": [64, 32], "out_channels": 3,
                 "conv_bias": False, "bn_eps": 1e-5},
        "tiny": {"widths": [8, 12, 16], "blocks": 1, "tail_widths": [16, 12], "out_channels": 3,
                 "conv_bias": True, "bn_eps": 1e-5},
    },
    # Learned texture inpainter: the MSN's structure (pix2pix resnet_9blocks at thesis size) with
    # channels + 1 inputs (texture with unknown texels 0, then the known mask ±1) and channels outputs.
    "inpaint": {
        "thesis": {"widths": [64, 128, 256], "blocks": 9, "channels": 3, "conv_bias": False, "bn_eps": 1e-5},
        "tiny": {"widths": [8, 12, 16], "blocks": 2, "channels": 3, "conv_bias": True, "bn_eps": 1e-5},
    },
}


def preset(net, name):
    """Returns a fresh copy of the config of preset ``name`` (``thesis`` | ``lite`` | ``tiny``) for ``net``
    (``lite``, the embedded default, exists for irn, msn and envmap only)."""
    if net not in PRESETS:
        raise ValueError(f"unknown net {net!r}; expected one of {NETS}")
    if name not in PRESETS[net]:
        raise ValueError(f"unknown preset {name!r} for {net}; expected one of {tuple(PRESETS[net])}")
    return copy.deepcopy(PRESETS[net][name])


# Bounds of every configuration (picker_nets::config::{MAX_WIDTH, MAX_BLOCKS, MAX_HEADS}).
MAX_WIDTH = 16384
MAX_BLOCKS = 1024
MAX_HEADS = 64


def validate_config(net, config):
    """Raises ValueError unless ``config`` has exactly the contract's keys for ``net`` and sane values."""
    expected = CONFIG_KEYS[net]
    if set(config) != set(expected):
        raise ValueError(f"{net} config keys {sorted(config)} != contract keys {sorted(expected)}")
    if not isinstance(config["conv_bias"], bool) or not config["bn_eps"] > 0:
        raise ValueError(f"conv_bias must be a bool and bn_eps > 0, got {config}")
    if len(config["widths"]) != 3 or min(config["widths"]) < 1 or max(config["widths"]) > MAX_WIDTH:
        raise ValueError(f"widths must be three ints in 1..={MAX_WIDTH}, got {config['widths']}")
    if not 0 <= config["blocks"] <= MAX_BLOCKS:
        raise ValueError(f"blocks must be in 0..={MAX_BLOCKS}, got {config['blocks']}")
    for key in ("out_channels", "channels"):
        if key in config and not 1 <= config[key] <= MAX_WIDTH:
            raise ValueError(f"{key} must be in 1..={MAX_WIDTH}, got {config[key]}")
    if net == "envmap" and not all(1 <= t <= MAX_WIDTH for t in config["tail_widths"]):
        raise ValueError(f"tail_widths must be ints in 1..={MAX_WIDTH}, got {config['tail_widths']}")
    if net == "irn":
        names = [h["name"] for h in config["heads"]]
        if not names or len(set(names)) != len(names):
            raise ValueError(f"head names must be non-empty and unique, got {names}")
        if len(names) > MAX_HEADS:
            raise ValueError(f"at most {MAX_HEADS} heads, got {len(names)}")
        for h in config["heads"]:
            if set(h) != {"name", "channels"} or not 1 <= h["channels"] <= MAX_WIDTH:
                raise ValueError(f"bad head {h}")
    if net == "inpaint" and config["channels"] < 1:
        raise ValueError(f"channels must be >= 1, got {config['channels']}")
    if net == "envmap" and len(config["tail_widths"]) != 2:
        raise ValueError(f"tail_widths must have two entries, got {config['tail_widths']}")


def config_json(config):
    """The config as the compact JSON string stored in the weights metadata (key order as given)."""
    return json.dumps(config, separators=(",", ":"))


def _conv(cin, cout, k):
    """Parameters of one conv after BatchNorm folding: weight + one bias per output channel."""
    return cin * cout * k * k + cout


def net_of_config(config):
    """Which net a config describes, from its keys (``heads`` → irn, ``tail_widths`` → envmap,
    ``channels`` → inpaint, else msn)."""
    if "heads" in config:
        return "irn"
    if "channels" in config:
        return "inpaint"
    return "envmap" if "tail_widths" in config else "msn"


def in_channels(net, config):
    """Input planes of the net: 3 (normalised RGB), or channels + 1 for the inpainter (texture + mask)."""
    return config["channels"] + 1 if net == "inpaint" else 3


def count_params_folded(config):
    """Parameters of the inference network after BatchNorm folding: sum over convs of (weights + c_out).

    Matches the contract's count: thesis IRN 108,856,080, MSN 11,378,179, EnvMap 5,463,427,
    inpaint 11,381,315.
    """
    net = net_of_config(config)
    validate_config(net, config)
    w0, w1, w2 = config["widths"]
    encoder = _conv(in_channels(net, config), w0, 7) + _conv(w0, w1, 3) + _conv(w1, w2, 3)
    blocks = config["blocks"] * 2 * _conv(w2, w2, 3)

    def decoder(c):
        return _conv(w2, w1, 3) + _conv(w1, w0, 3) + _conv(w0, c, 7)

    if net == "irn":
        return encoder + sum(blocks + decoder(h["channels"]) for h in config["heads"])
    if net == "msn":
        return encoder + blocks + decoder(config["out_channels"])
    if net == "inpaint":
        return encoder + blocks + decoder(config["channels"])
    t0, t1 = config["tail_widths"]
    return encoder + blocks + _conv(w2, t0, 1) + _conv(t0, t1, 3) + _conv(t1, config["out_channels"], 3)
