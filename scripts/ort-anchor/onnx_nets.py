#!/usr/bin/env python3
"""IRN, MSN or EnvMap (docs/contract.md) as an ONNX graph with random weights and BatchNorm folded.

The graph is built from the same config dicts as the PyTorch reference (``training/presets.py``), so the
layer shapes are the contract's; weights are random (He-normal, 0.2× on the second conv of each ResBlock,
BN statistics folded into conv weight and bias), seeded, float32, NCHW, static input [1, 3, H, W].

    python onnx_nets.py --net msn --size 240x320 --out /tmp/ort-anchor-cache/msn.onnx

writes the model and a ``.json`` sidecar (FLOPs = 2×MAC of the convs, parameter count, node count).
Only numpy and onnx are needed (no torch). Keep the files out of the repository: IRN is ~435 MB.
"""

import argparse
import json
import os
import sys

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
from training.presets import NETS, count_params_folded, preset  # noqa: E402

OPSET = 17
OUTPUT_NAMES = {"msn": "segmentation", "envmap": "envmap"}


class GraphBuilder:
    """Emits ONNX nodes and random initializers while tracking shapes and conv FLOPs."""

    def __init__(self, seed, eps):
        self.rng = np.random.default_rng(seed)
        self.eps = eps
        self.nodes, self.inits, self.shapes = [], [], {}
        self.flops = 0
        self.params = 0
        self._count = 0

    def _fresh(self, kind):
        self._count += 1
        return f"{kind}{self._count}"

    def _const(self, name, array):
        self.inits.append(numpy_helper.from_array(array, name))
        return name

    def input(self, name, shape):
        self.shapes[name] = shape
        return name

    def reflect_pad(self, x, p):
        n, c, h, w = self.shapes[x]
        y = self._fresh("pad")
        pads = self._const(y + "_pads", np.array([0, 0, p, p, 0, 0, p, p], dtype=np.int64))
        self.nodes.append(helper.make_node("Pad", [x, pads], [y], mode="reflect"))
        self.shapes[y] = (n, c, h + 2 * p, w + 2 * p)
        return y

    def conv(self, x, cout, k, stride, pad, act, bn=True, transpose=False, w_scale=1.0, name=None):
        """Conv (or 3×3 stride-2 ConvTranspose, output_padding 1) with BN folded, then ``act``."""
        n, cin, h, w = self.shapes[x]
        if transpose:
            ho, wo = (h - 1) * stride - 2 * pad + k + 1, (w - 1) * stride - 2 * pad + k + 1
            self.flops += 2 * cin * cout * k * k * h * w
            fan_in = cin * k * k / (stride * stride)
            weight = self.rng.standard_normal((cin, cout, k, k), dtype=np.float32)
        else:
            ho, wo = (h + 2 * pad - k) // stride + 1, (w + 2 * pad - k) // stride + 1
            self.flops += 2 * cout * ho * wo * cin * k * k
            fan_in = cin * k * k
            weight = self.rng.standard_normal((cout, cin, k, k), dtype=np.float32)
        weight *= np.float32(np.sqrt(2.0 / fan_in) * w_scale)
        bias = np.zeros(cout, np.float32)
        if bn:
            gamma = self.rng.uniform(0.5, 1.5, cout).astype(np.float32)
            beta = self.rng.normal(0.0, 0.1, cout).astype(np.float32)
            mean = self.rng.normal(0.0, 0.1, cout).astype(np.float32)
            var = self.rng.uniform(0.5, 1.5, cout).astype(np.float32)
            scale = gamma / np.sqrt(var + np.float32(self.eps))
            weight *= scale[None, :, None, None] if transpose else scale[:, None, None, None]
            bias = (bias - mean) * scale + beta
        self.params += weight.size + bias.size
        y = name or self._fresh("conv")
        pre = y if act is None else y + "_pre"
        attrs = dict(kernel_shape=[k, k], strides=[stride, stride], pads=[pad] * 4)
        if transpose:
            attrs["output_padding"] = [1, 1]
        inputs = [x, self._const(y + "_w", weight), self._const(y + "_b", bias)]
        self.nodes.append(helper.make_node("ConvTranspose" if transpose else "Conv", inputs, [pre], **attrs))
        if act is not None:
            self.nodes.append(helper.make_node({"relu": "Relu", "tanh": "Tanh"}[act], [pre], [y]))
        self.shapes[y] = (n, cout, ho, wo)
        return y

    def add(self, a, b):
        y = self._fresh("add")
        self.nodes.append(helper.make_node("Add", [a, b], [y]))
        self.shapes[y] = self.shapes[a]
        return y

    def resize_bilinear(self, x, size, name):
        """Bilinear resize to ``size`` (rows, cols) with half-pixel centres (align_corners=False)."""
        n, c, _, _ = self.shapes[x]
        sizes = self._const(name + "_sizes", np.array([n, c, *size], dtype=np.int64))
        self.nodes.append(helper.make_node("Resize", [x, "", "", sizes], [name], mode="linear",
                                           coordinate_transformation_mode="half_pixel"))
        self.shapes[name] = (n, c, *size)
        return name

    # ------------------------------------------------------------------ contract blocks
    def encoder(self, x, widths, stride0):
        x = self.conv(self.reflect_pad(x, 3), widths[0], 7, stride0, 0, "relu")
        x = self.conv(x, widths[1], 3, 2, 1, "relu")
        return self.conv(x, widths[2], 3, 2, 1, "relu")

    def resblocks(self, x, count):
        c = self.shapes[x][1]
        for _ in range(count):
            h = self.conv(self.reflect_pad(x, 1), c, 3, 1, 0, "relu")
            h = self.conv(self.reflect_pad(h, 1), c, 3, 1, 0, None, w_scale=0.2)
            x = self.add(x, h)
        return x

    def decoder(self, x, widths, channels, name):
        x = self.conv(x, widths[1], 3, 2, 1, "relu", transpose=True)
        x = self.conv(x, widths[0], 3, 2, 1, "relu", transpose=True)
        return self.conv(self.reflect_pad(x, 3), channels, 7, 1, 0, "tanh", bn=False, name=name)


def build_graph(net, config, h, w, seed=0):
    """Returns (onnx.ModelProto, info dict) for ``net`` with ``config`` at input size h×w."""
    b = GraphBuilder(seed, config["bn_eps"])
    x = b.input("input", (1, 3, h, w))
    widths = config["widths"]
    if net == "irn":
        features = b.encoder(x, widths, 1)
        outputs = [b.decoder(b.resblocks(features, config["blocks"]), widths, head["channels"], head["name"])
                   for head in config["heads"]]
    elif net == "msn":
        y = b.resblocks(b.encoder(x, widths, 1), config["blocks"])
        outputs = [b.decoder(y, widths, config["out_channels"], OUTPUT_NAMES[net])]
    else:
        y = b.resblocks(b.encoder(x, widths, 2), config["blocks"])
        t0, t1 = config["tail_widths"]
        y = b.conv(y, t0, 1, 2, 0, "relu")
        y = b.conv(y, t1, 3, 2, 1, "relu")
        y = b.conv(y, config["out_channels"], 3, 2, 1, "tanh")
        outputs = [b.resize_bilinear(y, (max(1, h // 8), max(1, w // 8)), OUTPUT_NAMES[net])]
    graph = helper.make_graph(
        b.nodes, f"{net}_{h}x{w}", [helper.make_tensor_value_info(x, TensorProto.FLOAT, list(b.shapes[x]))],
        [helper.make_tensor_value_info(o, TensorProto.FLOAT, list(b.shapes[o])) for o in outputs],
        initializer=b.inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="material-picker ort-anchor")
    model.ir_version = 8
    expected = count_params_folded(config)
    if b.params != expected:
        raise RuntimeError(f"{net}: graph has {b.params} parameters, the contract's count is {expected}")
    info = dict(net=net, size=f"{h}x{w}", seed=seed, flops=b.flops, params=b.params, nodes=len(b.nodes),
                outputs=outputs)
    return model, info


def check_size(net, h, w):
    """The bench graph has no padding: the size must already be one the contract's nets accept as is."""
    if net == "envmap":
        ok = h >= 16 and w >= 16
    else:
        ok = h >= 8 and w >= 8 and h % 4 == 0 and w % 4 == 0
    if not ok:
        raise ValueError(f"{net}: size {h}x{w} needs padding (IRN/MSN: multiples of 4, >= 8; EnvMap: >= 16)")


def write_model(net, h, w, path, seed=0):
    """Builds the thesis-preset model and writes ``path`` (atomically) plus ``<path minus .onnx>.json``."""
    check_size(net, h, w)
    model, info = build_graph(net, preset(net, "thesis"), h, w, seed)
    tmp = path + ".tmp"
    onnx.save_model(model, tmp)
    os.replace(tmp, path)
    info["bytes"] = os.path.getsize(path)
    with open(os.path.splitext(path)[0] + ".json", "w") as f:
        json.dump(info, f)
    return info


def parse_size(text):
    """'240x320' → (240, 320)."""
    h, w = text.lower().split("x")
    return int(h), int(w)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--net", choices=NETS, required=True)
    ap.add_argument("--size", default="240x320", help="HxW of the input")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True, help="path of the .onnx file to write")
    args = ap.parse_args()
    info = write_model(args.net, *parse_size(args.size), args.out, args.seed)
    print(json.dumps(info))


if __name__ == "__main__":
    main()
