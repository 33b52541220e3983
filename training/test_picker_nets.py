"""Self-test of the PyTorch reference nets, padding policy and conventions.

Run from the repository root with plain Python (or pytest)::

    /tmp/venv/bin/python -m training.test_picker_nets
"""

import json
import os
import tempfile

import torch
from safetensors import safe_open
from torch import nn

from training import conventions as conv
from training.picker_nets import (
    build,
    conv_modules,
    count_params_folded,
    forward_any,
    mirror_indices,
    mirror_pad,
    named_outputs,
    preset,
    save_weights,
)

THESIS_PARAMS = {"irn": 108_856_080, "msn": 11_378_179, "envmap": 5_463_427, "inpaint": 11_381_315}


def _count_modules(model):
    """Σ over convs of (weight numel + c_out), from the built modules."""
    total = 0
    for _, m in conv_modules(model):
        c_out = m.out_channels
        total += m.weight.numel() + c_out
    return total


def test_thesis_param_counts():
    for net, expected in THESIS_PARAMS.items():
        config = preset(net, "thesis")
        assert count_params_folded(config) == expected, (net, count_params_folded(config))
        with torch.device("meta"):  # shapes only: the thesis IRN would take 435 MB
            model = build(net, config)
        assert _count_modules(model) == expected, net


def test_tiny_counts_agree():
    for net in THESIS_PARAMS:
        config = preset(net, "tiny")
        assert _count_modules(build(net, config)) == count_params_folded(config), net


def test_state_dict_keys():
    irn = build("irn", preset("irn", "tiny")).state_dict()
    assert list(irn)[:7] == ["enc.conv_in.conv.weight", "enc.conv_in.conv.bias", "enc.conv_in.bn.weight",
                             "enc.conv_in.bn.bias", "enc.conv_in.bn.running_mean",
                             "enc.conv_in.bn.running_var", "enc.conv_in.bn.num_batches_tracked"]
    assert irn["heads.normals.blocks.1.conv2.weight"].shape == (16, 16, 3, 3)
    assert irn["heads.uv.dec.up.0.conv.weight"].shape == (16, 12, 3, 3)  # ConvTranspose: [cin, cout, k, k]
    assert irn["heads.glossiness.dec.conv_out.weight"].shape == (1, 8, 7, 7)
    assert irn["heads.glossiness.dec.conv_out.bias"].shape == (1,)
    nbt = irn["enc.down.1.bn.num_batches_tracked"]
    assert nbt.dtype == torch.int64 and nbt.shape == ()
    # per ConvBn/ConvTBn/ResBlock conv: conv weight+bias, BN 5 tensors; conv_out: weight+bias
    per_head = 2 * 2 * 7 + 2 * 7 + 2
    assert len(irn) == 3 * 7 + 6 * per_head

    msn = build("msn", preset("msn", "tiny")).state_dict()
    assert "enc.conv_in.conv.bias" not in msn and "dec.conv_out.bias" in msn
    assert {k.rsplit(".", 2)[0] for k in msn if k.startswith("blocks.")} == {"blocks.0", "blocks.1"}

    env = build("envmap", preset("envmap", "tiny")).state_dict()
    assert env["tail.0.conv.weight"].shape == (16, 16, 1, 1)
    assert env["tail.2.conv.weight"].shape == (3, 12, 3, 3) and "tail.2.bn.running_var" in env
    assert not any(k.startswith("dec.") for k in env)

    inp = build("inpaint", preset("inpaint", "tiny")).state_dict()
    assert inp["enc.conv_in.conv.weight"].shape == (8, 4, 7, 7)  # texture planes + mask
    assert inp["dec.conv_out.weight"].shape == (3, 8, 7, 7) and "enc.conv_in.conv.bias" in inp
    msn_keys = set(build("msn", dict(preset("msn", "tiny"), conv_bias=True)).state_dict())
    assert set(inp) == msn_keys


def test_unknown_config_key_rejected():
    config = preset("msn", "tiny")
    config["dropout"] = 0.5
    try:
        build("msn", config)
    except ValueError:
        return
    raise AssertionError("unknown key accepted")


def test_tiny_forward_shapes():
    torch.manual_seed(0)
    irn = build("irn", preset("irn", "tiny")).eval()
    out = irn(torch.rand(1, 3, 24, 32) * 2 - 1)
    assert list(out) == [h["name"] for h in preset("irn", "tiny")["heads"]]
    assert out["glossiness"].shape == (1, 1, 24, 32) and out["uv"].shape == (1, 3, 24, 32)
    msn = build("msn", preset("msn", "tiny")).eval()
    assert msn(torch.zeros(2, 3, 20, 28)).shape == (2, 3, 20, 28)
    env = build("envmap", preset("envmap", "tiny")).eval()
    assert env(torch.zeros(1, 3, 40, 56)).shape == (1, 3, 5, 7)
    assert forward_any(env, torch.zeros(1, 3, 13, 30)).shape == (1, 3, 1, 3)
    assert forward_any(env, torch.zeros(1, 3, 1, 5)).shape == (1, 3, 1, 1)
    assert forward_any(msn, torch.zeros(1, 3, 21, 27)).shape == (1, 3, 21, 27)
    inp = build("inpaint", preset("inpaint", "tiny")).eval()
    assert forward_any(inp, torch.zeros(1, 4, 21, 27)).shape == (1, 3, 21, 27)


def test_forward_any_is_identity_on_valid_sizes():
    torch.manual_seed(1)
    x = torch.rand(1, 3, 24, 32, dtype=torch.float64) * 2 - 1
    with torch.no_grad():
        irn = build("irn", preset("irn", "tiny")).double().eval()
        plain, anysize = irn(x), forward_any(irn, x)
        assert all(torch.equal(plain[k], anysize[k]) for k in plain)
        msn = build("msn", preset("msn", "tiny")).double().eval()
        assert torch.equal(msn(x), forward_any(msn, x))
        env = build("envmap", preset("envmap", "tiny")).double().eval()
        x = torch.rand(1, 3, 40, 56, dtype=torch.float64)
        assert torch.equal(env(x), forward_any(env, x))


def test_mirror_indices():
    # pads smaller than the size: torch's reflect pad
    x = torch.arange(35.0).reshape(1, 1, 5, 7)
    assert torch.equal(mirror_pad(x, 2, 4, 3, 1), nn.functional.pad(x, (3, 1, 2, 4), mode="reflect"))
    # periodic continuation with period 2(n-1) when the pad exceeds n-1
    assert mirror_indices(3, 5, 6).tolist() == [1, 0, 1, 2, 1, 0, 1, 2, 1, 0, 1, 2, 1, 0]
    assert mirror_indices(2, 3, 3).tolist() == [1, 0, 1, 0, 1, 0, 1, 0]
    assert mirror_indices(1, 2, 3).tolist() == [0] * 6


def test_conventions():
    y = torch.linspace(-1, 1, 5)
    assert torch.allclose(conv.to_unit(y), torch.tensor([0.0, 0.25, 0.5, 0.75, 1.0]))
    assert conv.phong_exponent(torch.tensor(-1.0)) == 1.0 and conv.phong_exponent(torch.tensor(1.0)) == 8192.0
    assert conv.env_radiance(torch.tensor(-1.0)) == 0.0
    assert torch.isclose(conv.env_radiance(torch.tensor(1.0, dtype=torch.float64)),
                         torch.tensor(1000.0, dtype=torch.float64))
    r = torch.tensor([0.0, 0.5, 20.0, 999.0], dtype=torch.float64)
    assert torch.allclose(conv.env_radiance(conv.encode_env_radiance(r)), r)
    n = torch.tensor([1.0, 17.0, 8192.0], dtype=torch.float64)
    assert torch.allclose(conv.phong_exponent(conv.encode_phong_exponent(n)), n)
    v = conv.unit_vectors(torch.tensor([[[[0.3]], [[-0.4]], [[0.0]]]]))
    assert torch.allclose(v.flatten(), torch.tensor([0.6, -0.8, 0.0]))
    uvt = conv.texture_coords(torch.tensor([[[1.0]], [[-1.0]], [[1.0]]]))
    assert uvt.flatten().tolist() == [0.0, 0.0, 1.0]  # u = 1 wraps to 0; t is not wrapped
    assert conv.encode_input(torch.tensor(1.0)) == 1.0
    x = conv.inpaint_input(torch.tensor([[[[0.0, 1.0]], [[0.25, 0.5]], [[1.0, 0.75]]]]), [[True, False]])
    assert x.flatten().tolist() == [-1.0, 0.0, -0.5, 0.0, 1.0, 0.0, 1.0, -1.0]


def test_save_weights_metadata_and_bytes():
    model = build("envmap", preset("envmap", "tiny"))
    with tempfile.TemporaryDirectory() as d:
        paths = [os.path.join(d, f"{i}.safetensors") for i in range(2)]
        for p in paths:
            save_weights(model, "envmap", "tiny", preset("envmap", "tiny"), p, dtype=torch.bfloat16,
                         extra_metadata={"created_by": "test"})
        data = [open(p, "rb").read() for p in paths]
        assert data[0] == data[1]
        with safe_open(paths[0], "pt") as f:
            meta = f.metadata()
            assert meta["format"] == "material-picker" and meta["format_version"] == "1"
            assert meta["net"] == "envmap" and meta["preset"] == "tiny" and meta["created_by"] == "test"
            assert json.loads(meta["config"]) == preset("envmap", "tiny")
            assert f.get_tensor("tail.1.bn.running_var").dtype == torch.bfloat16
            assert f.get_tensor("tail.1.bn.num_batches_tracked").dtype == torch.int64
            assert set(f.keys()) == set(model.state_dict())


def test_parity_fixtures_reproduce():
    """The committed fixtures agree with a float32 run of these modules on the stored weights."""
    root = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "fixtures", "parity")
    names = ["irn_tiny", "msn_tiny", "envmap_tiny", "msn_tiny_f16", "envmap_tiny_bf16", "inpaint_tiny"]
    dtypes = {"msn_tiny_f16": torch.float16, "envmap_tiny_bf16": torch.bfloat16}
    for name in names:
        with safe_open(os.path.join(root, f"{name}.safetensors"), "pt") as f:
            meta = f.metadata()
            state = {k: f.get_tensor(k) for k in f.keys()}
        assert meta["created_by"] == "training/make_fixtures.py" and meta["preset"] == "tiny"
        floats = {v.dtype for v in state.values() if v.is_floating_point()}
        assert floats == {dtypes.get(name, torch.float32)}, (name, floats)
        model = build(meta["net"], json.loads(meta["config"]))
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state.items()})
        model.eval()
        with safe_open(os.path.join(root, f"{name}_io.safetensors"), "pt") as f:
            io = {k: f.get_tensor(k) for k in f.keys()}
        assert all(v.dtype == torch.float32 for v in io.values())
        for key in [k for k in io if k.startswith("input")]:
            suffix = key[len("input"):]
            with torch.no_grad():
                out = named_outputs(model.net, forward_any(model, io[key]))
            assert {f"out{suffix}.{k}" for k in out} == {k for k in io if k.startswith(f"out{suffix}.")}
            for head, y in out.items():
                err = (y - io[f"out{suffix}.{head}"]).abs().max().item()
                assert err < 1e-4, (name, suffix, head, err)


def main():
    tests = [(name, fn) for name, fn in globals().items() if name.startswith("test_") and callable(fn)]
    for name, fn in tests:
        fn()
        print(f"ok  {name}")
    print(f"{len(tests)} tests passed")


if __name__ == "__main__":
    main()
