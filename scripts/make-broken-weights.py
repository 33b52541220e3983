#!/usr/bin/env python3
"""Writes the corpus of broken weights files in fixtures/weights/broken/.

Every file is derived from the committed tiny weights in fixtures/weights/tiny/
(the small MSN and EnvMap files) by one targeted change, so each one exercises
exactly one error of the loader (crates/picker-nets/src/weights.rs and the
network loaders). crates/picker-nets/tests/broken_corpus.rs loads every file
and checks its message; fixtures/weights/broken/README.md lists them.

Standard library only. Usage, from the repository root:

    python3 scripts/make-broken-weights.py [--out fixtures/weights/broken]

The output is deterministic: re-running it rewrites identical files.
"""

import argparse
import json
import os
import struct
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = os.path.join(ROOT, "fixtures", "weights", "tiny")

DTYPE_SIZE = {"F64": 8, "F32": 4, "F16": 2, "BF16": 2, "I64": 8, "I32": 4, "U8": 1}


def read(name):
    """Parses tiny/<name>.safetensors into (metadata, [[key, dtype, shape, bytes], ...])."""
    with open(os.path.join(TINY, name + ".safetensors"), "rb") as f:
        blob = f.read()
    (n,) = struct.unpack("<Q", blob[:8])
    header = json.loads(blob[8 : 8 + n])
    data = blob[8 + n :]
    meta = header.pop("__metadata__", None)
    tensors = []
    for key, info in sorted(header.items(), key=lambda kv: kv[1]["data_offsets"]):
        s, e = info["data_offsets"]
        tensors.append([key, info["dtype"], list(info["shape"]), data[s:e]])
    return meta, tensors


def header_bytes(header):
    """The JSON header padded with spaces to a multiple of 8 bytes, as safetensors writes it."""
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 8)
    return text


def serialize(meta, tensors):
    """A well-formed safetensors file: contiguous data in list order."""
    header = {}
    if meta is not None:
        header["__metadata__"] = meta
    offset = 0
    for key, dtype, shape, data in tensors:
        header[key] = {"dtype": dtype, "shape": shape, "data_offsets": [offset, offset + len(data)]}
        offset += len(data)
    return raw(header, b"".join(t[3] for t in tensors))


def raw(header, data):
    """A file from a header dict taken as is (offsets are not recomputed)."""
    text = header_bytes(header)
    return struct.pack("<Q", len(text)) + text + data


def find(tensors, key):
    for t in tensors:
        if t[0] == key:
            return t
    raise KeyError(key)


def replace_f32(data, index, value):
    return data[: 4 * index] + struct.pack("<f", value) + data[4 * index + 4 :]


def build():
    """Returns {file name: bytes}."""
    out = {}
    msn_meta, msn = read("msn")
    env_meta, env = read("envmap")

    # --- Tensor-level errors: a complete EnvMap file with one tensor changed. ---
    t = [list(x) for x in env if x[0] != "tail.1.bn.running_var"]
    out["missing_tensor.safetensors"] = serialize(env_meta, t)

    t = [list(x) for x in env] + [["optimizer.lr", "F32", [1], struct.pack("<f", 1e-3)]]
    out["extra_tensor.safetensors"] = serialize(env_meta, t)

    t = [list(x) for x in env]
    find(t, "blocks.0.conv2.weight")[2] = [16, 16, 9]  # [16, 16, 3, 3], same bytes
    out["wrong_shape.safetensors"] = serialize(env_meta, t)

    t = [list(x) for x in env]
    find(t, "tail.2.conv.bias")[1] = "I32"  # F32 [3] -> I32 [3], same 12 bytes
    out["wrong_dtype.safetensors"] = serialize(env_meta, t)

    t = [list(x) for x in env]
    e = find(t, "tail.2.conv.bias")
    e[1], e[3] = "F64", struct.pack("<3d", *struct.unpack("<3f", e[3]))
    out["wrong_dtype_f64.safetensors"] = serialize(env_meta, t)

    t = [list(x) for x in env]
    e = find(t, "blocks.0.conv1.weight")
    e[3] = replace_f32(e[3], 5, float("nan"))
    out["nan_values.safetensors"] = serialize(env_meta, t)

    t = [list(x) for x in env]
    e = find(t, "tail.1.bn.running_var")
    e[3] = replace_f32(e[3], 2, -0.5)
    out["negative_variance.safetensors"] = serialize(env_meta, t)

    t = [["module." + x[0]] + list(x[1:]) for x in env]
    out["key_prefix.safetensors"] = serialize(env_meta, t)

    full = serialize(env_meta, [list(x) for x in env])
    out["truncated.safetensors"] = full[:-100]  # cut inside the data
    out["trailing_bytes.safetensors"] = full + b"\0" * 16

    # --- Wrong network: a complete, valid MSN file, loaded where an IRN is expected. ---
    out["wrong_net.safetensors"] = serialize(msn_meta, [list(x) for x in msn])

    # --- Header-level errors: small files (the loader stops before reading tensors). ---
    one = [list(find(env, "tail.2.conv.bias"))]  # F32 [3]
    small = serialize(env_meta, one)
    (n,) = struct.unpack("<Q", small[:8])

    out["truncated_header.safetensors"] = small[: 8 + n // 2]
    out["header_len_huge.safetensors"] = struct.pack("<Q", 1 << 63) + small[8:]
    out["header_len_1tb.safetensors"] = struct.pack("<Q", 10**12) + small[8:]

    # A tensor declaring 2^80 elements: the element count overflows.
    h = {"__metadata__": env_meta,
         "tail.2.conv.bias": {"dtype": "F32", "shape": [1 << 40, 1 << 40], "data_offsets": [0, 12]}}
    out["tensor_shape_huge.safetensors"] = raw(h, one[0][3])

    # A tensor declaring 2^40 elements (4 TiB) backed by 12 bytes.
    h = {"__metadata__": env_meta,
         "tail.2.conv.bias": {"dtype": "F32", "shape": [1 << 20, 1 << 20], "data_offsets": [0, 12]}}
    out["tensor_shape_large.safetensors"] = raw(h, one[0][3])

    # Consistent shape and offsets, but the range lies far beyond the end of the file.
    h = {"__metadata__": env_meta,
         "tail.2.conv.bias": {"dtype": "F32", "shape": [3], "data_offsets": [0, 12]},
         "tail.2.conv.weight": {"dtype": "F32", "shape": [250000, 1], "data_offsets": [12, 1000012]}}
    out["offsets_out_of_range.safetensors"] = raw(h, one[0][3])

    # A tensor ending at byte 2^64 - 1 of the data: adding the header length overflows.
    h = {"__metadata__": env_meta,
         "tail.2.conv.bias": {"dtype": "U8", "shape": [(1 << 64) - 1], "data_offsets": [0, (1 << 64) - 1]}}
    out["offsets_overflow.safetensors"] = raw(h, one[0][3])

    # The second tensor starts inside the first (distinct starts keep the message deterministic).
    h = {"__metadata__": env_meta,
         "tail.2.conv.bias": {"dtype": "F32", "shape": [3], "data_offsets": [0, 12]},
         "tail.1.conv.bias": {"dtype": "F32", "shape": [3], "data_offsets": [8, 20]}}
    out["overlapping_offsets.safetensors"] = raw(h, one[0][3] + one[0][3][:8])

    text = b'{"__metadata__": {format: material-picker}}'
    text += b" " * (-len(text) % 8)
    out["not_json_header.safetensors"] = struct.pack("<Q", len(text)) + text

    h = {"tail.2.conv.bias": {"dtype": "F32", "shape": [3]}}  # no data_offsets
    out["malformed_entry.safetensors"] = raw(h, b"")

    out["missing_metadata.safetensors"] = serialize(None, one)  # a plain save_file, no metadata

    m = dict(env_meta, format_version="2")
    out["bad_metadata_version.safetensors"] = serialize(m, one)

    m = dict(env_meta, format="pt")
    out["wrong_format.safetensors"] = serialize(m, one)

    cfg = json.loads(env_meta["config"])
    cfg["dropout"] = 0.5
    m = dict(env_meta, config=json.dumps(cfg, separators=(",", ":")))
    out["config_unknown_key.safetensors"] = serialize(m, one)

    cfg = json.loads(env_meta["config"])
    cfg["blocks"] = 3
    m = dict(env_meta, config=json.dumps(cfg, separators=(",", ":")))  # still labelled "tiny"
    out["preset_mismatch.safetensors"] = serialize(m, one)

    # A valid config declaring a network of ~10^20 parameters: nothing may be sized by it.
    cfg = json.loads(env_meta["config"])
    cfg["widths"] = [1 << 32] * 3
    cfg["tail_widths"] = [1 << 32] * 2
    m = dict(env_meta, config=json.dumps(cfg, separators=(",", ":")), preset="custom")
    out["config_huge_widths.safetensors"] = serialize(m, one)

    out["empty.safetensors"] = b""
    out["text_file.txt"] = b"These are not weights: a text file given where a .safetensors file belongs.\n"
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "fixtures", "weights", "broken"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    files = build()
    total = 0
    for name, data in sorted(files.items()):
        with open(os.path.join(args.out, name), "wb") as f:
            f.write(data)
        total += len(data)
    print(f"wrote {len(files)} files, {total} bytes, to {os.path.relpath(args.out)}", file=sys.stderr)


if __name__ == "__main__":
    main()
