"""Self-test of the trainer (training/train.py, synth_data.py, evaluate.py) on fixtures/synth (two 24×32 scenes).

    /tmp/venv/bin/python -m training.test_train          # ~30 s on one thread

Reading and masks, target encoding round trips, reduction and mirroring conventions, a 4-step run that lowers
the loss, bit-identical resume, export → ``picker weights inspect --check`` and ``picker infer`` (binary from
$PICKER_BIN, else target*/release/picker; skipped with a message when absent), the evaluation helper.
"""

import csv
import glob
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import torch

from training import conventions as conv
from training import device_data
from training import evaluate, train
from training import synth_data as sd

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FIXTURES = os.path.join(ROOT, "fixtures", "synth")
SCENE0 = os.path.join(FIXTURES, "scene_000000")
SCENE1 = os.path.join(FIXTURES, "scene_000001")


def close(a, b, tol=1e-5):
    d = float((torch.as_tensor(a) - torch.as_tensor(b)).abs().max())
    assert d <= tol, f"max |a - b| = {d} > {tol}"


def test_reading():
    r = sd.load_scene(SCENE0, "irn")
    assert r["image"].shape == (3, 24, 32) and 0 <= r["image"].min() and r["image"].max() <= 1
    for name, c in [("diffuse_albedo", 3), ("specular_albedo", 3), ("normals", 3), ("glossiness", 1),
                    ("view_vector", 3), ("uv", 3)]:
        assert r[name].shape == (c, 24, 32), (name, r[name].shape)
    close(np.linalg.norm(r["normals"], axis=0), 1.0)
    assert r["surface"].all()  # scene 0 sees no sky
    r1 = sd.load_scene(SCENE1, "irn")
    sky = r1["surface"][0] == 0
    assert sky.sum() == 355, sky.sum()  # material id 0 in material_id.png
    assert (r1["diffuse_albedo"][:, sky] == 0).all() and (r1["textured"][0][sky] == 0).all()
    assert set(np.unique(r["uv"][2])) <= {0.0, 1.0} and (r["uv"][:2] >= 0).all() and (r["uv"][:2] <= 1).all()
    env = sd.load_scene(SCENE0, "envmap")["envmap"]
    assert env.shape == (3, 3, 4) and env.min() >= 0, env.shape  # 1/8 of 24x32
    seg = sd.load_scene(SCENE1, "msn")["segmentation"]
    assert seg.shape == (3, 24, 32) and (seg[:, sky] == 0).all()
    assert sd.seeds_of(sd.list_scenes([FIXTURES])) == [2026]


def test_encoding_round_trip():
    r = sd.load_scene(SCENE1, "irn")
    r.update(sd.load_scene(SCENE1, "envmap"))
    r["segmentation"] = sd.load_scene(SCENE1, "msn")["segmentation"]
    t = sd.encode_targets(r)
    for name in ("diffuse_albedo", "specular_albedo", "normals", "glossiness", "view_vector", "uv", "segmentation",
                 "envmap"):
        assert t[name].min() >= -1 and t[name].max() <= 1, name
    for name in ("diffuse_albedo", "specular_albedo", "glossiness", "segmentation"):
        close(conv.to_unit(t[name]), r[name])
    close(conv.unit_vectors(t["normals"]), r["normals"])
    close(conv.unit_vectors(t["view_vector"]), r["view_vector"])
    uvt = conv.texture_coords(t["uv"])
    u = torch.from_numpy(r["uv"])
    close(uvt[2], u[2])
    wrapped = (uvt[:2] - u[:2]).abs()
    close(torch.minimum(wrapped, 1 - wrapped), 0.0)  # u = 1.0 (f32 wrap rounding) decodes to 0
    close(conv.env_radiance(t["envmap"]) / (1 + torch.from_numpy(r["envmap"])),
          torch.from_numpy(r["envmap"]) / (1 + torch.from_numpy(r["envmap"])), 1e-4)
    g = torch.tensor([0.0, 0.3, 1.0])
    close(conv.encode_phong_exponent(conv.phong_exponent(conv.from_unit(g))), conv.from_unit(g), 1e-5)


class _Always:
    """A stand-in for numpy's Generator: crops at the origin, mirrors always."""

    def integers(self, lo, hi):
        return lo

    def random(self):
        return 0.0


def test_reduce_and_mirror():
    raw = sd.load_scene(SCENE1, "irn")
    raw.update(sd.load_scene(SCENE1, "envmap"))
    plain = sd.prepare(raw, (24, 32), None, flip=False, crop="centre")
    mirrored = sd.prepare(raw, (24, 32), _Always(), flip=True)
    close(mirrored["input"], plain["input"].flip(-1))
    close(mirrored["normals"][0], -plain["normals"][0].flip(-1))
    close(mirrored["normals"][1:], plain["normals"][1:].flip(-1))
    close(mirrored["view_vector"][0], -plain["view_vector"][0].flip(-1))
    close(mirrored["uv"], plain["uv"].flip(-1))
    close(mirrored["envmap"], plain["envmap"].flip(-1))
    close(mirrored["surface"], plain["surface"].flip(-1))
    half = sd.prepare(raw, (12, 16), None, flip=False, crop="centre")  # factor 2
    assert half["input"].shape == (3, 12, 16) and half["envmap"].shape == (3, 1, 2)
    close(half["input"], conv.encode_input(torch.from_numpy(raw["image"]).reshape(3, 12, 2, 16, 2).mean((2, 4))))
    close(torch.linalg.vector_norm(half["normals"], dim=0), 1.0)
    s = torch.from_numpy(raw["surface"][0]).reshape(12, 2, 16, 2)
    close(half["surface"][0], s.amin((1, 3)))
    close(half["uv"], sd.encode_targets({"uv": raw["uv"][:, 1::2, 1::2]})["uv"])
    sd.check_disjoint({"train": [SCENE0], "val": []})
    try:
        sd.check_disjoint({"train": [SCENE0], "val": [SCENE1]})
        raise AssertionError("shared seeds were not refused")
    except ValueError as e:
        assert "2026" in str(e)


def _run(out, *extra):
    return train.main(["--net", "irn", "--preset", "tiny", "--data", FIXTURES, "--size", "24x32", "--steps", "4",
                       "--batch", "2", "--threads", "1", "--log-every", "1", "--quiet", "--out", out, *extra])


def _losses(run_dir):
    with open(os.path.join(run_dir, "train.csv"), newline="") as f:
        return [float(r["loss"]) for r in csv.DictReader(f)]


def _refused(argv, expected, what):
    """``train.main(argv)`` must exit with a message containing ``expected``; ``what`` names the case."""
    try:
        train.main(argv)
    except SystemExit as e:
        assert expected in str(e), e
        return
    raise AssertionError(what)


def test_mixed_scene_sizes():
    """Stages larger than some scenes draw only from the scenes that are large enough; none: a clear error."""
    ds = sd.SynthDataset([SCENE0, SCENE1], "msn", 3, lambda k: (24, 32) if k < 4 else (12, 16))
    assert ds.eligible((24, 32)) is None and ds.eligible((12, 16)) is None
    try:
        ds.eligible((48, 64))
        raise AssertionError("a size larger than every scene was accepted")
    except ValueError as e:
        assert "no training scene is at least 48x64" in str(e), e
    # Pretend scene 1 were 48×64: at 48×64 only it is drawn, at 24×32 both, in the unchanged order.
    ds._sizes = [(24, 32), (48, 64)]
    ds._eligible.clear()
    assert ds.eligible((48, 64)) == [1]
    assert {ds.scene_index(k, (48, 64)) for k in range(6)} == {1}
    plain = sd.SynthDataset([SCENE0, SCENE1], "msn", 3, None)
    assert [ds.scene_index(k, (24, 32)) for k in range(6)] == [plain.scene_index(k) for k in range(6)]


def test_training_and_resume(tmp):
    straight = os.path.join(tmp, "straight")
    path = _run(straight, "--no-flip")
    losses = _losses(straight)
    assert len(losses) == 4 and losses[-1] < losses[0], losses
    assert os.path.exists(path) and glob.glob(os.path.join(straight, "samples", "*.png"))
    # Interrupted after 2 steps, resumed: bit-identical weights and optimiser state.
    parted = os.path.join(tmp, "parted")
    assert _run(parted, "--no-flip", "--until", "2") is None
    assert not os.path.exists(os.path.join(parted, "irn.safetensors"))
    train.main(["--resume", "--out", parted, "--threads", "1", "--quiet"])
    a = torch.load(os.path.join(straight, "checkpoints", "last.pt"), weights_only=False)
    b = torch.load(os.path.join(parted, "checkpoints", "last.pt"), weights_only=False)
    assert a["step"] == b["step"] == 4
    for k in a["model"]:
        assert torch.equal(a["model"][k], b["model"][k]), k
    for i, st in a["optimizer"]["state"].items():
        for k, v in st.items():
            assert torch.equal(v, b["optimizer"]["state"][i][k]), (i, k)
    assert _losses(parted) == losses
    # Data-loader workers give the same batches (samples are functions of (seed, k)).
    workers = os.path.join(tmp, "workers")
    _run(workers, "--no-flip", "--workers", "2")
    c = torch.load(os.path.join(workers, "checkpoints", "last.pt"), weights_only=False)
    for k in a["model"]:
        assert torch.equal(a["model"][k], c["model"][k]), k
    return path


def test_other_nets(tmp):
    paths = {}
    for net in ("msn", "envmap"):
        out = os.path.join(tmp, net)
        paths[net] = train.main(["--net", net, "--preset", "tiny", "--data", FIXTURES, "--size", "24x32",
                                 "--steps", "4", "--batch", "2", "--threads", "1", "--log-every", "1", "--quiet",
                                 "--out", out])
        losses = _losses(out)
        assert losses[-1] < losses[0], (net, losses)
    return paths


def test_init(tmp, msn_path):
    """--init starts from a file's tensors (step 0 = the file's outputs), records the history, refuses a mismatch."""
    out = os.path.join(tmp, "msn-ft")
    args = ["--net", "msn", "--preset", "tiny", "--data", FIXTURES, "--size", "24x32", "--batch", "2",
            "--threads", "1", "--log-every", "1", "--quiet", "--no-flip"]
    # Zero steps of fine-tuning is impossible (a run takes at least one), so compare the first logged loss
    # with the same batch's loss of the starting file: equal to float precision, unlike a random start.
    path = train.main([*args, "--steps", "2", "--init", msn_path, "--out", out])
    _, start, _ = evaluate.load_weights(msn_path)
    first = _losses(out)[0]
    fresh = os.path.join(tmp, "msn-fresh")
    train.main([*args, "--steps", "1", "--out", fresh])
    ds = sd.SynthDataset(sd.list_scenes([FIXTURES]), "msn", 0, lambda k: (24, 32), flip=False)
    b = torch.utils.data.default_collate([ds[0], ds[1]])
    start.train()
    with torch.no_grad():
        expect = float(train.losses("msn", start, b, ["segmentation"], {})[0])
    assert abs(first - expect) < 1e-4 * max(1.0, expect), (first, expect)
    assert abs(_losses(fresh)[0] - expect) > 1e-3, "a random start gave the starting file's loss"
    _, _, meta = evaluate.load_weights(path)
    init = json.loads(meta["training.init"])
    assert init["steps"] == 4 and init["data_seeds"] == [2026] and len(init["sha256"]) == 64, init
    assert meta["training.steps"] == "6", meta["training.steps"]
    # Another net's file, or the same net with another config: refused before training.
    _refused([*args, "--steps", "1", "--init", msn_path, "--out", os.path.join(tmp, "bad"), "--net", "envmap"],
             "holds 'msn' weights", "an msn file started an envmap run")
    _refused([*args, "--steps", "1", "--init", msn_path, "--out", os.path.join(tmp, "bad2"),
              "--preset", "lite"],
             "differs from the run's", "a tiny file started a lite run")


def test_embedding():
    """Material labels from the target colours; the discriminative loss is 0 for well-separated materials,
    positive for merged or spread ones, and its gradient is finite."""
    from training import embedding as em

    h, w = 6, 8
    seg = torch.full((2, 3, h, w), -0.5)
    seg[0, :, :, 4:] = 0.25                # image 0: two materials, left and right
    seg[0, :, 0, 0] = 0.9                  # one pixel of a rare colour: ignored
    surface = torch.ones(2, 1, h, w)
    surface[1, :, :3] = 0                  # image 1: one material, top half sky
    lab = em.labels_of(seg, surface)
    assert lab.shape == (2, h, w) and lab.dtype == torch.long
    assert lab[0, 0, 0] == -1 and (lab[1, :3] == -1).all() and (lab[1, 3:] == lab[1, 3, 0]).all()
    left, right = int(lab[0, 1, 0]), int(lab[0, 1, 7])
    assert left != right and (lab[0, 1:, :4] == left).all() and (lab[0, :, 4:] == right).all()
    emb = torch.zeros(2, 3, h, w)
    emb[0, 0, :, :4], emb[0, 0, :, 4:] = -0.5, 0.5   # 1.0 apart ≥ 2·δd = 0.8, no spread
    pull, push, reg = em.discriminative_loss(emb, lab)
    assert float(pull) == 0.0 and float(push) == 0.0, (pull, push)
    assert abs(float(reg) - 0.25) < 1e-6, reg  # image 0: means 0.5 from the origin; image 1: at it
    merged = torch.zeros(2, 3, h, w)
    pull, push, _ = em.discriminative_loss(merged, lab)
    assert float(pull) == 0.0 and abs(float(push) - 0.8 ** 2) < 1e-6, push
    spread = emb.clone()
    spread[0, 1, :, 1] = 0.6                          # one column 0.6 off its mean (minus its own share)
    assert float(em.discriminative_loss(spread, lab)[0]) > 0
    x = (torch.randn(2, 3, h, w) * 0.1).requires_grad_()
    em.embedding_loss(x, seg, surface).backward()
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0
    # No material anywhere: zero loss, still differentiable.
    none = em.embedding_loss(x, seg, torch.zeros(2, 1, h, w))
    assert float(none) == 0.0 and none.requires_grad


def test_init_widen(tmp, msn_path):
    """An MSN run with a material embedding (6 outputs) starts from a 3-output file: its colours as the file's
    (the first loss equals the file's on the same batch), the embedding trained alongside."""
    cfg_path = os.path.join(tmp, "embed.json")
    model = {"widths": [8, 12, 16], "blocks": 2, "out_channels": 6, "conv_bias": False, "bn_eps": 1e-5}
    with open(cfg_path, "w") as f:
        json.dump({"model": model}, f)
    out = os.path.join(tmp, "msn-embed")
    path = train.main(["--net", "msn", "--config", cfg_path, "--data", FIXTURES, "--size", "24x32", "--batch",
                       "2", "--threads", "1", "--log-every", "1", "--quiet", "--no-flip", "--steps", "2",
                       "--init", msn_path, "--out", out])
    with open(os.path.join(out, "train.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    assert "embedding" in rows[0] and float(rows[0]["embedding"]) > 0, rows[0]
    _, start, _ = evaluate.load_weights(msn_path)
    ds = sd.SynthDataset(sd.list_scenes([FIXTURES]), "msn", 0, lambda k: (24, 32), flip=False)
    b = torch.utils.data.default_collate([ds[0], ds[1]])
    start.train()
    with torch.no_grad():
        expect = float(train.losses("msn", start, b, ["segmentation"], {})[0])
    first = float(rows[0]["segmentation"])
    assert abs(first - expect) < 1e-4 * max(1.0, expect), (first, expect)
    _, done, meta = evaluate.load_weights(path)
    assert json.loads(meta["config"])["out_channels"] == 6
    with torch.no_grad():
        y = done(b["input"])
    assert y.shape[1] == 6 and set(train.named_outputs("msn", y)) == {"segmentation", "embedding"}
    # Only the output may widen: a file of another width is refused.
    assert not train.widens("msn", {**model, "out_channels": 3, "blocks": 3}, model)
    assert not train.widens("envmap", {**model, "out_channels": 3}, model)
    assert train.widens("msn", {**model, "out_channels": 3}, model)


def test_stage_lr(tmp):
    """A stage's own "lr" applies to its steps (a step schedule), the run's elsewhere; bad values are refused."""
    cfg = os.path.join(tmp, "sched.json")
    with open(cfg, "w") as f:
        json.dump({"lr": 1e-3, "stages": [{"size": [24, 32], "steps": 2, "lr": 5e-4},
                                          {"size": [24, 32], "steps": 2}]}, f)
    out = os.path.join(tmp, "sched")
    train.main(["--net", "msn", "--preset", "tiny", "--data", FIXTURES, "--config", cfg, "--batch", "2",
                "--threads", "1", "--log-every", "1", "--quiet", "--out", out])
    with open(os.path.join(out, "train.csv"), newline="") as f:
        lrs = [float(r["lr"]) for r in csv.DictReader(f)]
    assert lrs == [5e-4, 5e-4, 1e-3, 1e-3], lrs
    with open(cfg, "w") as f:
        json.dump({"stages": [{"size": [24, 32], "steps": 2, "lr": 0}]}, f)
    _refused(["--net", "msn", "--preset", "tiny", "--data", FIXTURES, "--config", cfg, "--quiet",
              "--out", os.path.join(tmp, "sched-bad")],
             "lr must be a positive number", "a stage with lr 0 was accepted")


def picker_bin():
    cands = [os.environ.get("PICKER_BIN", "")] + [os.path.join(ROOT, p, "release", "picker")
                                                  for p in ("target", "../target-main")]
    return next((c for c in cands if c and os.access(c, os.X_OK)), None)


def test_export_loads_in_rust(tmp, irn_path, other_paths):
    wdir = os.path.join(tmp, "weights")
    os.makedirs(wdir)
    for p in [irn_path, *other_paths.values()]:
        shutil.copy(p, wdir)
    net, _, meta = evaluate.load_weights(irn_path)
    assert net == "irn" and meta["preset"] == "tiny" and json.loads(meta["training.data_seeds"]) == [2026]
    assert meta["training.steps"] == "4" and "training.date" in meta and "train_loss" in meta["training.metrics"]
    from safetensors import safe_open
    with safe_open(irn_path, framework="pt") as f:
        assert f.get_tensor("enc.conv_in.conv.weight").dtype == torch.float16
    exe = picker_bin()
    if exe is None:
        print("  SKIPPED: no picker binary (set PICKER_BIN) for the Rust load check")
        return
    for f in sorted(os.listdir(wdir)):
        r = subprocess.run([exe, "weights", "inspect", os.path.join(wdir, f), "--check"], capture_output=True,
                           text=True)
        assert r.returncode == 0 and "check:       ok" in r.stdout, r.stdout + r.stderr
    out = os.path.join(tmp, "infer")
    r = subprocess.run([exe, "infer", os.path.join(ROOT, "fixtures", "examples", "coffee.jpg"), "--weights", wdir,
                        "--out", out, "--threads", "1"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    for name in ("diffuse_albedo.exr", "segmentation.exr", "envmap.exr"):
        assert os.path.exists(os.path.join(out, name)), name


def test_evaluate(tmp, irn_path, other_paths):
    out = os.path.join(tmp, "metrics.json")
    res = evaluate.main(["--weights", irn_path, "--weights", other_paths["msn"], "--weights", other_paths["envmap"],
                         "--data", FIXTURES, "--out", out, "--allow-overlap", "--threads", "1"])
    for k in ("albedo_si_mse", "normals_deg", "uv_error", "uv_t_accuracy", "envmap_log_l1", "segmentation_l1"):
        m = res["metrics"][k]
        assert m["scenes"] == 2 and np.isfinite(m["model"]) and np.isfinite(m["baseline"]), (k, m)
    assert json.load(open(out))["test_seeds"] == [2026]
    assert 0 < res["metrics"]["normals_deg"]["baseline"] < 90
    try:
        evaluate.main(["--weights", irn_path, "--data", FIXTURES, "--threads", "1"])
        raise AssertionError("evaluation on training seeds was not refused")
    except SystemExit as e:
        assert "2026" in str(e)


def test_device_batches(tmp):
    """DeviceData (scenes on the device, batches made there) gives the CPU reader's samples; packs give the
    same batches as the synth folders they were made of."""
    pack_dir = os.path.join(tmp, "pack")
    meta = device_data.pack(FIXTURES, pack_dir, workers=2)
    assert meta["count"] == 2 and (meta["height"], meta["width"]) == (24, 32) and meta["seeds"] == [2026, 2026]
    assert not os.path.exists(pack_dir + ".tmp") and device_data.is_pack(pack_dir)
    assert device_data.source_seeds([pack_dir]) == [2026] == device_data.source_seeds([FIXTURES])
    try:
        device_data.pack(FIXTURES, pack_dir)
        raise AssertionError("packing over an existing pack was accepted")
    except FileExistsError:
        pass
    for net in ("irn", "msn", "envmap"):
        dd = device_data.DeviceData([FIXTURES], net, 7, "cpu")
        dp = device_data.DeviceData([pack_dir], net, 7, "cpu")
        for size in ((24, 32), (12, 16), (16, 16), (20, 28), (8, 12)):
            cpu = sd.SynthDataset(sd.list_scenes([FIXTURES]), net, 7, lambda k, size=size: size)
            ks = range(3, 11)
            want = torch.utils.data.default_collate([cpu[k] for k in ks])
            got, got_pack = dd.batch(ks, size), dp.batch(ks, size)
            assert set(got) == set(want), (net, sorted(got), sorted(want))
            for name in want:
                assert got[name].shape == want[name].shape, (net, size, name, got[name].shape, want[name].shape)
                assert torch.equal(got[name], got_pack[name]), (net, size, name)
                if name in ("surface", "textured"):
                    assert torch.equal(got[name], want[name]), (net, size, name)
                else:
                    close(got[name], want[name], 3e-3)
    # Crops and mirrors really vary: two sample numbers of one scene differ.
    dd = device_data.DeviceData([FIXTURES], "irn", 7, "cpu")
    a = dd.batch(range(0, 8), (16, 16))["input"]
    assert len({tuple(x.flatten()[:64].tolist()) for x in a}) > 2
    try:
        dd.eligible((48, 64))
        raise AssertionError("a stage larger than every scene was accepted")
    except ValueError as e:
        assert "48x64" in str(e), e


def test_augment():
    x = torch.rand(6, 3, 8, 10) * 2 - 1
    same = device_data.augment_photometric(x, 1, 5, {"p": 0.0})
    assert torch.equal(same, x)
    a = device_data.augment_photometric(x, 1, 5, {"p": 1.0})
    b = device_data.augment_photometric(x, 1, 5, {"p": 1.0})
    c = device_data.augment_photometric(x, 1, 6, {"p": 1.0})
    assert torch.equal(a, b) and not torch.equal(a, c)
    assert a.min() >= -1 and a.max() <= 1 and (a - x).abs().mean() > 1e-3
    # Without noise and colour change, a gain of one is the identity up to the sRGB round trip.
    d = device_data.augment_photometric(x, 1, 5, {"p": 1.0, "exposure": [1.0, 1.0], "white_balance": 0.0,
                                                  "noise": 0.0})
    close(d, x, 1e-5)
    # Vignetting: 0 is the old behaviour bit for bit; otherwise the corners darken, the centre hardly.
    assert torch.equal(device_data.augment_photometric(x, 1, 5, {"p": 1.0, "vignette": 0.0}), a)
    flat = torch.full((4, 3, 30, 40), 0.6)
    plain = {"p": 1.0, "exposure": [1.0, 1.0], "white_balance": 0.0, "noise": 0.0}
    v = device_data.augment_photometric(flat, 2, 7, dict(plain, vignette=0.8))
    assert torch.equal(v, device_data.augment_photometric(flat, 2, 7, dict(plain, vignette=0.8)))
    corners = v[:, :, [0, 0, -1, -1], [0, -1, 0, -1]]
    assert (corners <= 0.6 + 1e-5).all() and (corners < 0.6 - 1e-3).any(), corners
    assert (v[:, :, 14:16, 19:21] - 0.6).abs().max() < 0.05
    assert v.min() >= -1 and (v <= 0.6 + 1e-5).all()
    # Camera effects: absent or zero is the old behaviour bit for bit; each is deterministic and stays in range.
    zero = {"p": 1.0, "vignette": 0.0, "blur": 0.0, "tone": 0.0, "saturation": 0.0, "jpeg": None}
    assert torch.equal(device_data.augment_photometric(x, 1, 5, zero), a)
    cam = {"p": 1.0, "blur": 1.5, "tone": 0.3, "saturation": 0.3, "jpeg": [40, 90]}
    e = device_data.augment_photometric(x, 3, 9, cam)
    assert torch.equal(e, device_data.augment_photometric(x, 3, 9, cam))
    assert e.min() >= -1 and e.max() <= 1 and not torch.equal(e, device_data.augment_photometric(x, 3, 10, cam))
    # Blur keeps a flat image flat and the mean of any image (reflected borders: nearly), and smooths.
    bl = device_data.gaussian_blur(flat, [0.0, 0.7, 1.5, 3.0])
    close(bl, flat, 1e-5)
    step = torch.zeros(2, 3, 20, 20)
    step[:, :, :, 10:] = 1.0
    sm = device_data.gaussian_blur(step, [0.0, 2.0])
    assert torch.equal(sm[0], step[0])
    assert 0.05 < sm[1, 0, 5, 9] < 0.5 < sm[1, 0, 5, 10] < 0.95 and sm[1, 0, 5, 0] < 1e-4
    # Any size, a single row or pixel too (a blur wider than the image).
    one = torch.rand(2, 3, 1, 5)
    assert device_data.gaussian_blur(one, [2.0, 0.0]).shape == one.shape
    close(device_data.gaussian_blur(torch.full((1, 3, 1, 1), 0.3), [1.5]), torch.full((1, 3, 1, 1), 0.3), 1e-6)
    # JPEG: quality 0 is the identity; a smooth image survives a high quality closely.
    grad = torch.linspace(0, 1, 32)[None, None, None, :].repeat(2, 3, 16, 1)
    j = device_data.jpeg_roundtrip(grad, [0, 95])
    assert torch.equal(j[0], grad[0]) and (j[1] - grad[1]).abs().max() < 0.03
    # Tone and saturation alone keep grey pixels grey and black black.
    g = torch.full((3, 3, 4, 4), -1.0)
    g[:, :, :2] = 0.2
    t = device_data.augment_photometric(g, 4, 1, dict(plain, tone=0.4, saturation=0.5))
    assert (t[:, 0] - t[:, 1]).abs().max() < 1e-6 and (t[:, :, 2:] == -1).all()


def test_device_training(tmp):
    """A run on DeviceData: a stage of seconds becomes a step count in the config and the export; the loss
    falls; steps-based runs repeat and resume bit-identically on CPU."""
    cfg = os.path.join(tmp, "dev.json")
    with open(cfg, "w") as f:
        json.dump({"device_data": True, "augment": {"p": 0.5}, "batch": 2, "log_every": 1,
                   "stages": [{"size": [24, 32], "seconds": 0.5}, {"size": [16, 16], "steps": 2, "lr": 1e-4}]}, f)
    out = os.path.join(tmp, "dev")
    path = train.main(["--net", "irn", "--preset", "tiny", "--config", cfg, "--data", FIXTURES, "--threads", "1",
                       "--quiet", "--out", out])
    from safetensors import safe_open  # noqa: PLC0415
    with safe_open(path, framework="pt") as f:
        meta = f.metadata()
    stages = json.loads(meta["training.recipe"])["stages"]
    first = stages[0]["steps"]
    assert first >= 1 and stages[0]["seconds"] == 0.5 and stages[1]["steps"] == 2, stages
    assert int(meta["training.steps"]) == first + 2
    recipe = json.loads(meta["training.recipe"])
    assert recipe["augment"] == {"p": 0.5} and recipe["device_data"] is True and "amp" not in recipe, recipe
    with open(os.path.join(out, "train.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["step"]) for r in rows] == list(range(1, first + 3))
    assert [r["height"] for r in rows[-2:]] == ["16", "16"] and rows[-1]["lr"] == "0.0001"
    # Steps only: repeatable and resumable bit for bit.
    with open(cfg, "w") as f:
        json.dump({"device_data": True, "augment": {"p": 0.5}, "batch": 2, "log_every": 1,
                   "stages": [{"size": [24, 32], "steps": 3}, {"size": [16, 16], "steps": 2}]}, f)
    common = ["--net", "irn", "--preset", "tiny", "--config", cfg, "--data", FIXTURES, "--threads", "1", "--quiet"]
    runs = [os.path.join(tmp, n) for n in ("dev-a", "dev-b", "dev-c")]
    train.main(common + ["--out", runs[0]])
    train.main(common + ["--out", runs[1]])
    assert train.main(common + ["--out", runs[2], "--until", "4"]) is None
    train.main(["--resume", "--out", runs[2], "--threads", "1", "--quiet"])
    losses = _losses(runs[0])
    assert losses[-1] < losses[0], losses
    ck = [torch.load(os.path.join(r, "checkpoints", "last.pt"), weights_only=False) for r in runs]
    for k in ck[0]["model"]:
        assert torch.equal(ck[0]["model"][k], ck[1]["model"][k]), k
        assert torch.equal(ck[0]["model"][k], ck[2]["model"][k]), k
    assert _losses(runs[2]) == losses
    _refused(["--net", "envmap", "--preset", "tiny", "--config", cfg, "--data", FIXTURES, "--quiet",
              "--out", os.path.join(tmp, "env-aug")],
             "EnvMap", "augmenting the EnvMap's input was accepted")
    with open(cfg, "w") as f:
        json.dump({"device_data": True, "augment": {"p": 0.5, "vignete": 0.5}, "batch": 2,
                   "stages": [{"size": [16, 16], "steps": 1}]}, f)
    _refused(["--net", "msn", "--preset", "tiny", "--config", cfg, "--data", FIXTURES, "--quiet",
              "--out", os.path.join(tmp, "typo")],
             "vignete", "a misspelt augmentation key was accepted")


def test_stage_data(tmp):
    """Stage data: read when its stage begins (waiting for a pack made meanwhile), counted in the export's
    seeds, resumable bit for bit before and after the stage that reads it; a pack that never comes fails."""
    import threading  # noqa: PLC0415

    late = os.path.join(tmp, "late-pack")
    threading.Timer(1.0, lambda: device_data.pack(FIXTURES, late)).start()
    cfg = os.path.join(tmp, "stage-data.json")
    with open(cfg, "w") as f:
        json.dump({"device_data": True, "batch": 2, "log_every": 1, "data_wait_s": 60,
                   "stages": [{"size": [24, 32], "steps": 2}, {"size": [16, 16], "steps": 2}]}, f)
    common = ["--net", "msn", "--preset", "tiny", "--config", cfg, "--data", SCENE0, "--stage-data", "1", late,
              "--threads", "1", "--quiet"]
    runs = [os.path.join(tmp, n) for n in ("sd-a", "sd-b", "sd-c")]
    path = train.main(common + ["--out", runs[0]])
    from safetensors import safe_open  # noqa: PLC0415
    with safe_open(path, framework="pt") as f:
        meta = f.metadata()
    assert json.loads(meta["training.data_seeds"]) == [2026], meta["training.data_seeds"]
    assert json.loads(meta["training.recipe"])["stages"][1]["data"] == [late]
    for out, until in ((runs[1], "1"), (runs[2], "3")):
        assert train.main(common + ["--out", out, "--until", until]) is None
        train.main(["--resume", "--out", out, "--threads", "1", "--quiet"])
    ck = [torch.load(os.path.join(r, "checkpoints", "last.pt"), weights_only=False) for r in runs]
    for k in ck[0]["model"]:
        assert torch.equal(ck[0]["model"][k], ck[1]["model"][k]), k
        assert torch.equal(ck[0]["model"][k], ck[2]["model"][k]), k
    # The stage data were trained on: without them stage 1 draws from SCENE0 alone, other weights.
    alone = os.path.join(tmp, "sd-alone")
    train.main(common[:common.index("--stage-data")] + common[common.index("--stage-data") + 3:] + ["--out", alone])
    other = torch.load(os.path.join(alone, "checkpoints", "last.pt"), weights_only=False)["model"]
    assert any(not torch.equal(other[k], ck[0]["model"][k]) for k in other)
    # A signal while waiting for stage data: checkpoint, stop; the export's seeds are those read.
    with open(cfg, "w") as f:
        json.dump({"device_data": True, "batch": 2, "data_wait_s": 60,
                   "stages": [{"size": [24, 32], "steps": 1}, {"size": [16, 16], "steps": 1}]}, f)
    waiting = os.path.join(tmp, "sd-wait")
    threading.Timer(1.5, signal.raise_signal, (signal.SIGINT,)).start()
    assert train.main(["--net", "msn", "--preset", "tiny", "--config", cfg, "--data", SCENE0, "--stage-data", "1",
                       os.path.join(tmp, "never"), "--threads", "1", "--quiet", "--out", waiting]) is None
    path = train.main(["--export-only", "--out", waiting, "--quiet"])
    with safe_open(path, framework="pt") as f:
        assert json.loads(f.metadata()["training.steps"]) == 1
    with open(cfg, "w") as f:
        json.dump({"device_data": True, "batch": 2, "data_wait_s": 1,
                   "stages": [{"size": [24, 32], "steps": 1}, {"size": [16, 16], "steps": 1}]}, f)
    _refused(["--net", "msn", "--preset", "tiny", "--config", cfg, "--data", SCENE0, "--stage-data", "1",
              os.path.join(tmp, "never"), "--threads", "1", "--quiet", "--out", os.path.join(tmp, "sd-never")],
             "not there after 1 s", "a stage whose data never came")
    _refused(["--net", "msn", "--preset", "tiny", "--config", cfg, "--data", SCENE0, "--stage-data", "2", late,
              "--quiet", "--out", os.path.join(tmp, "sd-bad")], "no stage 2", "stage data for a stage that is not")


def main():
    torch.set_num_threads(1)
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        results = {}

        def step(name, fn, *a):
            t = time.perf_counter()
            results[name] = fn(*a)
            print(f"ok  {name} ({time.perf_counter() - t:.1f} s)", flush=True)
            return results[name]

        step("reading", test_reading)
        step("encoding round trip", test_encoding_round_trip)
        step("reduce and mirror", test_reduce_and_mirror)
        step("mixed scene sizes", test_mixed_scene_sizes)
        irn = step("4-step run lowers the loss; resume and workers are bit-identical", test_training_and_resume, tmp)
        others = step("msn and envmap runs lower the loss", test_other_nets, tmp)
        step("a stage's lr is a step schedule", test_stage_lr, tmp)
        step("--init fine-tunes from a weights file", test_init, tmp, others["msn"])
        step("material embedding: labels and discriminative loss", test_embedding)
        step("--init widens an MSN's output to a material embedding", test_init_widen, tmp, others["msn"])
        step("export loads and runs in picker", test_export_loads_in_rust, tmp, irn, others)
        step("evaluate", test_evaluate, tmp, irn, others)
        step("device data: the CPU reader's batches, packs", test_device_batches, tmp)
        step("photometric augmentation", test_augment)
        step("device-data runs: stages of seconds, repeatable, resumable", test_device_training, tmp)
        step("stage data: read when its stage begins, resumable", test_stage_data, tmp)
    print(f"all passed in {time.perf_counter() - t_all:.1f} s")


if __name__ == "__main__":
    sys.exit(main())
