"""Reading `picker synth` scene folders as training samples: inputs, tanh-space targets, masks, augmentation.

A scene folder ``scene_NNNNNN/`` (``crates/picker-synth/src/output.rs``) holds, per element, an EXR with the exact
f32 values and a PNG for viewing. This module reads:

====================  ==============================  =====================================================
file                  values                          target (tanh space, :mod:`training.conventions` inverse)
====================  ==============================  =====================================================
``image.png``         8-bit sRGB                      network input x = 2·srgb − 1
``diffuse_albedo``    linear ρd (RGB)                 2ρd − 1
``specular_albedo``   linear ρs (RGB)                 2ρs − 1
``glossiness``        g ∈ [0, 1] (Y)                  2g − 1
``normals``           unit camera-space vector        the vector itself (components in [-1, 1])
``view_vector``       unit camera-space vector        the vector itself
``uv``                (u, v, t)                       2·(u, v, t) − 1
``segmentation``      (ρd* + ρs)/2 of the material    2·seg − 1 (MSN)
``envmap``            linear radiance, 1/8 size       2·ln(1 + L)/ln(1001) − 1, L clamped to [0, 1000]
``material_id.png``   16-bit material id, 0 = sky     masks
====================  ==============================  =====================================================

Masks (1 = the pixel counts in the loss): ``surface`` = material id > 0 (sky pixels have no albedo, normal or
glossiness: synth writes zeros / the view direction there); ``textured`` = surface and t = 1 (u, v are only
defined on textured materials; single-colour materials have u = v = 0). The view vector is defined on every
pixel (it is camera geometry), the segmentation too (synth writes 0 — black — for the sky, which the MSN learns as
a material of its own).

Resolution and augmentation (:func:`prepare`): a scene of H0×W0 is reduced by the integer factor
k = max(1, min(H0 // H, W0 // W)) to reach a training size H×W (so 240×320 data train at 120×160 as whole
views, multi-resolution fine-tuning then continues at 240×320 with k = 1), then a random H×W window is cut and,
optionally, the sample is mirrored left-right. The reduction box-averages the image (in sRGB, as a photo
downscale), albedos, glossiness and the unit vectors (renormalised), takes the block-centre sample of uv and
segmentation (averaging would blend unrelated materials or wrap-around coordinates), and keeps a block in a
mask only when all its pixels are in it. The mirror negates the x component of normals and view vectors and
mirrors the env map's columns (longitude φ → −φ is column j → W − 1 − j: exact); u and v keep their values:
the mirrored image shows the texture mirrored at the same (u, v), so scattering pixels by the predicted uv still
rebuilds the unmirrored texture.

All randomness of a sample is drawn from ``numpy.random.default_rng([seed, k])`` for the global sample
number k, so a run's data stream is a pure function of (seed, step): resuming needs no data-loader state,
and any number of loader workers gives the same batches.
"""

import json
import os

import numpy as np
import torch
import torch.nn.functional as F

from training import conventions as conv

IRN_ELEMENTS = ("diffuse_albedo", "specular_albedo", "normals", "glossiness", "view_vector", "uv")
"""The IRN heads of the presets, which are also the synth element names."""

ELEMENT_MASK = {
    "diffuse_albedo": "surface",
    "specular_albedo": "surface",
    "normals": "surface",
    "glossiness": "surface",
    "view_vector": "all",
    "uv": "uv",            # channels u, v on textured pixels; t on surface pixels
    "segmentation": "all",
    "envmap": "all",
}
"""Which mask each element's loss uses (see the module docs)."""

_EXR_CHANNELS = {
    "diffuse_albedo": 3, "specular_albedo": 3, "glossiness": 1, "normals": 3, "view_vector": 3, "uv": 3,
    "segmentation": 3, "envmap": 3,
}


def read_exr(path):
    """An EXR written by ``picker_render::io::write_exr`` as float32 [C, H, W] (channels R, G, B or Y)."""
    import OpenEXR  # noqa: PLC0415  (imported lazily: only the data reader needs it)

    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        if "RGB" in channels:
            a = np.asarray(channels["RGB"].pixels, dtype=np.float32)
            return np.ascontiguousarray(a.transpose(2, 0, 1))
        if "Y" in channels:
            return np.asarray(channels["Y"].pixels, dtype=np.float32)[None].copy()
        if all(c in channels for c in "RGB"):
            return np.stack([np.asarray(channels[c].pixels, dtype=np.float32) for c in "RGB"])
        raise ValueError(f"{path}: expected channels R,G,B or Y, found {sorted(channels)}")


def read_png(path):
    """A PNG as float32 [C, H, W] scaled to [0, 1] (8- or 16-bit)."""
    from PIL import Image  # noqa: PLC0415

    with Image.open(path) as im:
        if im.mode in ("I;16", "I;16B", "I;16L", "I"):
            a = np.asarray(im, dtype=np.uint16).astype(np.float32) / 65535.0
            return a[None]
        im = im.convert("RGB")
        return np.asarray(im, dtype=np.float32).transpose(2, 0, 1) / 255.0


def read_material_id(path):
    """``material_id.png`` (16-bit grey) as int32 [H, W]; 0 is the sky."""
    from PIL import Image  # noqa: PLC0415

    with Image.open(path) as im:
        return np.asarray(im, dtype=np.uint16).astype(np.int32)


def list_scenes(folders):
    """Sorted scene folders (``scene_*`` holding ``scene.json``) of each folder in ``folders`` (a folder that
    is itself a scene counts as one)."""
    scenes = []
    for folder in folders:
        folder = os.fspath(folder)
        if os.path.isfile(os.path.join(folder, "scene.json")):
            scenes.append(folder)
            continue
        if not os.path.isdir(folder):
            raise FileNotFoundError(f"{folder}: no such data folder")
        found = sorted(os.path.join(folder, d) for d in os.listdir(folder)
                       if d.startswith("scene_") and os.path.isfile(os.path.join(folder, d, "scene.json")))
        if not found:
            raise FileNotFoundError(f"{folder}: no scene_*/scene.json inside (a `picker synth --out` folder?)")
        scenes.extend(found)
    return scenes


def scene_info(scene_dir):
    """(seed, index, height, width) from a scene's ``scene.json``."""
    with open(os.path.join(scene_dir, "scene.json")) as f:
        j = json.load(f)
    return int(j["seed"]), int(j["index"]), int(j["height"]), int(j["width"])


def seeds_of(scenes):
    """Sorted distinct generator seeds of ``scenes``."""
    return sorted({scene_info(s)[0] for s in scenes})


def check_disjoint(named_scene_lists):
    """Raises ValueError when two splits (dict name → scene folders) share a generator seed."""
    seen = {}
    for name, scenes in named_scene_lists.items():
        for seed in seeds_of(scenes):
            if seed in seen and seen[seed] != name:
                raise ValueError(f"splits {seen[seed]!r} and {name!r} share the picker synth seed {seed}; "
                                 "train, validation and test data must come from different seeds")
            seen[seed] = name


def load_scene(scene_dir, net):
    """Raw arrays of one scene for ``net`` (float32 [C, H, W]): ``image`` (sRGB in [0, 1]), the element values
    as written by synth, ``surface`` and ``textured`` masks ([1, H, W])."""
    out = {"image": read_png(os.path.join(scene_dir, "image.png"))}
    mid = read_material_id(os.path.join(scene_dir, "material_id.png"))
    out["surface"] = (mid > 0).astype(np.float32)[None]
    if net == "irn":
        names = IRN_ELEMENTS
    elif net == "msn":
        names = ("segmentation",)
    elif net == "envmap":
        names = ("envmap",)
    else:
        raise ValueError(f"no synth targets for net {net!r}")
    for name in names:
        a = read_exr(os.path.join(scene_dir, f"{name}.exr"))
        if a.shape[0] != _EXR_CHANNELS[name]:
            raise ValueError(f"{scene_dir}/{name}.exr: {a.shape[0]} channels, expected {_EXR_CHANNELS[name]}")
        out[name] = a
    if "uv" in out:
        out["textured"] = out["surface"] * (out["uv"][2:3] >= 0.5)
    h, w = out["image"].shape[1:]
    for name, a in out.items():
        if name != "envmap" and a.shape[1:] != (h, w):
            raise ValueError(f"{scene_dir}: {name} is {a.shape[1:]}, image is {(h, w)}")
    return out


def encode_targets(raw):
    """Tanh-space targets (float32 tensors [C, H, W]) from the raw element values of :func:`load_scene`;
    the exact inverses of :mod:`training.conventions` (values clamped to the decodable range)."""
    t = {}
    for name, a in raw.items():
        x = a if torch.is_tensor(a) else torch.from_numpy(np.ascontiguousarray(a))
        if name in ("diffuse_albedo", "specular_albedo", "glossiness", "segmentation"):
            t[name] = conv.from_unit(x.clamp(0.0, 1.0))
        elif name == "uv":
            t[name] = conv.from_unit(x.clamp(0.0, 1.0))
        elif name in ("normals", "view_vector"):
            t[name] = conv.unit_vectors(x).clamp(-1.0, 1.0)
        elif name == "envmap":
            t[name] = conv.encode_env_radiance(x.clamp(0.0, conv.ENV_RADIANCE_MAX))
        elif name == "image":
            t[name] = conv.encode_input(x)
        else:  # masks
            t[name] = x
    return t


def decode_element(name, y):
    """Decoded values of an element from tanh values (for metrics and pictures)."""
    if name in ("diffuse_albedo", "specular_albedo", "glossiness", "segmentation"):
        return conv.to_unit(y)
    if name in ("normals", "view_vector"):
        return conv.unit_vectors(y)
    if name == "uv":
        return conv.texture_coords(y)
    if name == "envmap":
        return conv.env_radiance(y)
    raise ValueError(name)


def _box(a, k):
    c, h, w = a.shape
    return a[:, :h // k * k, :w // k * k].reshape(c, h // k, k, w // k, k).mean(axis=(2, 4))


def _centre(a, k):
    h, w = a.shape[1:]
    return a[:, k // 2:h // k * k:k, k // 2:w // k * k:k]


def _all(a, k):
    c, h, w = a.shape
    return a[:, :h // k * k, :w // k * k].reshape(c, h // k, k, w // k, k).min(axis=(2, 4))


def reduce_scene(raw, k):
    """Reduces a scene's arrays by the integer factor ``k`` (see the module docs); ``envmap`` is left as is."""
    if k == 1:
        return raw
    out = {}
    for name, a in raw.items():
        if name in ("image", "diffuse_albedo", "specular_albedo", "glossiness"):
            out[name] = _box(a, k)
        elif name in ("normals", "view_vector"):
            v = _box(a, k)
            out[name] = v / np.maximum(np.linalg.norm(v, axis=0, keepdims=True), 1e-12)
        elif name in ("uv", "segmentation"):
            out[name] = _centre(a, k)
        elif name in ("surface", "textured"):
            out[name] = _all(a, k)
        else:
            out[name] = a
    return out


def resize_envmap(env, size):
    """Resamples a [C, h, w] (or batched [B, C, h, w]) tensor env map to ``size`` = (rows, cols): area
    average for integer ratios, otherwise antialiased bilinear."""
    if tuple(env.shape[-2:]) == tuple(size):
        return env
    batch = env if env.dim() == 4 else env[None]
    h, w = env.shape[-2:]
    if h % size[0] == 0 and w % size[1] == 0:
        out = F.interpolate(batch, size=size, mode="area")
    else:
        out = F.interpolate(batch, size=size, mode="bilinear", align_corners=False, antialias=True)
    return out if env.dim() == 4 else out[0]


def reduction_factor(h0, w0, h, w):
    """The integer factor a h0×w0 scene is reduced by to train at h×w."""
    if h0 < h or w0 < w:
        raise ValueError(f"scene {h0}x{w0} is smaller than the training size {h}x{w}")
    return max(1, min(h0 // h, w0 // w))


def prepare(raw, size, rng, flip=True, crop="random"):
    """A training sample from the raw arrays of a scene: reduce, crop to ``size`` = (H, W), maybe mirror;
    returns tensors: ``input`` [3, H, W], the tanh-space targets and the masks (``envmap`` resized to the
    EnvMap net's output size (max(1, H//8), max(1, W//8)), in radiance before encoding)."""
    h, w = size
    h0, w0 = raw["image"].shape[1:]
    k = reduction_factor(h0, w0, h, w)
    r = reduce_scene(raw, k)
    hr, wr = r["image"].shape[1:]
    if crop == "random":
        top, left = int(rng.integers(0, hr - h + 1)), int(rng.integers(0, wr - w + 1))
    else:  # centre
        top, left = (hr - h) // 2, (wr - w) // 2
    mirror = bool(flip and rng.random() < 0.5)
    sample = {}
    for name, a in r.items():
        if name != "envmap":
            a = a[:, top:top + h, left:left + w]
            if mirror:
                a = a[:, :, ::-1]
                if name in ("normals", "view_vector"):
                    a = a * np.array([-1.0, 1.0, 1.0], dtype=np.float32)[:, None, None]
        elif mirror:
            a = a[:, :, ::-1]
        sample[name] = np.ascontiguousarray(a, dtype=np.float32)
    if "envmap" in sample:
        env = torch.from_numpy(sample["envmap"])
        sample["envmap"] = resize_envmap(env, (max(1, h // 8), max(1, w // 8))).numpy()
    t = encode_targets(sample)
    t["input"] = t.pop("image")
    return t


class SynthDataset(torch.utils.data.Dataset):
    """Samples of ``picker synth`` scenes for ``net``, indexed by the **global sample number** k.

    Sample k of a run is scene ``perm_e[k mod n]`` with e = k // n the epoch and ``perm_e`` a permutation drawn
    from ``default_rng([seed, e])``; its crop and mirror come from ``default_rng([seed, 2**32 + k])``. The
    training size is looked up per sample with ``size_of(k)`` (multi-resolution stages). Only scenes at least
    as large as that size are drawn (a 120×160 scene cannot give a 240×320 sample): when some scenes are too
    small, the permutation runs over the n' eligible ones and is drawn from ``default_rng([seed, e, H, W])``
    with e = k // n'. ``cache`` keeps the decoded scenes in memory (small datasets only). ``sizes`` (the
    (H, W) of each scene) saves reading each ``scene.json`` (:class:`training.device_data.DeviceData`).
    """

    def __init__(self, scenes, net, seed, size_of, flip=True, crop="random", shuffle=True, cache=False,
                 sizes=None):
        if not scenes:
            raise ValueError("no scenes")
        self.scenes, self.net, self.seed = list(scenes), net, int(seed)
        self.size_of, self.flip, self.crop, self.shuffle = size_of, flip, crop, shuffle
        self.cache = {} if cache else None
        self._perms = {}
        self._sizes = None if sizes is None else [tuple(v) for v in sizes]
        if self._sizes is not None and len(self._sizes) != len(self.scenes):
            raise ValueError(f"{len(self._sizes)} sizes for {len(self.scenes)} scenes")
        self._eligible = {}

    def __len__(self):
        return 1 << 62  # indexed by global sample number; the sampler bounds it

    def eligible(self, size):
        """Indices of the scenes at least ``size`` = (H, W) large (all of them: ``None``); raises ValueError
        when there is none."""
        size = tuple(size)
        if size not in self._eligible:
            if self._sizes is None:
                self._sizes = [scene_info(sc)[2:] for sc in self.scenes]
            idx = [i for i, (h, w) in enumerate(self._sizes) if h >= size[0] and w >= size[1]]
            if not idx:
                biggest = max(self._sizes)
                raise ValueError(f"no training scene is at least {size[0]}x{size[1]} (the largest is "
                                 f"{biggest[0]}x{biggest[1]}); generate data at that size for this stage")
            self._eligible[size] = None if len(idx) == len(self.scenes) else idx
        return self._eligible[size]

    def scene_index(self, k, size=None):
        subset = self.eligible(size) if size is not None else None
        n = len(self.scenes) if subset is None else len(subset)
        if not self.shuffle:
            j = k % n
        else:
            epoch = k // n
            key = (epoch,) if subset is None else (epoch, *size)
            perm = self._perms.get(key)
            if perm is None:
                perm = np.random.default_rng([self.seed, *key]).permutation(n)
                self._perms = {key: perm}
            j = int(perm[k % n])
        return j if subset is None else subset[j]

    def raw(self, i):
        if self.cache is not None and i in self.cache:
            return self.cache[i]
        r = load_scene(self.scenes[i], self.net)
        if self.cache is not None:
            self.cache[i] = r
        return r

    def __getitem__(self, k):
        size = tuple(self.size_of(k))
        i = self.scene_index(k, size)
        rng = np.random.default_rng([self.seed, (1 << 32) + int(k)])
        return prepare(self.raw(i), size, rng, flip=self.flip, crop=self.crop)


class RangeSampler(torch.utils.data.Sampler):
    """Yields the global sample numbers ``start, start + 1, …, stop − 1``."""

    def __init__(self, start, stop):
        self.start, self.stop = int(start), int(stop)

    def __iter__(self):
        return iter(range(self.start, self.stop))

    def __len__(self):
        return self.stop - self.start


def masked_l1(pred, target, mask):
    """Mean |pred − target| over the pixels where ``mask`` [N, 1, H, W] is 1 (all channels); 0 without any."""
    w = mask.expand_as(pred)
    return (torch.abs(pred - target) * w).sum() / w.sum().clamp_min(1.0)


def element_loss(name, pred, batch):
    """The L1 loss of one element (tanh space, masked as :data:`ELEMENT_MASK` says)."""
    target = batch[name]
    kind = ELEMENT_MASK.get(name, "all")
    if kind == "all":
        return torch.abs(pred - target).mean()
    if kind == "surface":
        return masked_l1(pred, target, batch["surface"])
    if kind == "uv":
        m_uv = batch["textured"].expand(-1, 2, -1, -1)
        m_t = batch["surface"]
        mask = torch.cat([m_uv, m_t], dim=1)
        return (torch.abs(pred - target) * mask).sum() / mask.sum().clamp_min(1.0)
    raise ValueError(kind)


def srgb_encode(x):
    """Linear → sRGB (clamped to [0, 1]), for pictures."""
    x = x.clamp(0.0, 1.0)
    return torch.where(x <= 0.0031308, 12.92 * x, 1.055 * x.clamp_min(1e-12) ** (1 / 2.4) - 0.055)


def srgb_decode(v):
    """sRGB in [0, 1] → linear."""
    return torch.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def tone_map(radiance):
    """Reinhard L/(1 + L) then sRGB, for env map pictures."""
    return srgb_encode(radiance / (1.0 + radiance))


def picture(name, y):
    """An element's tanh values [N, C, H, W] as a displayable RGB image in [0, 1]."""
    if name in ("diffuse_albedo", "specular_albedo"):
        return srgb_encode(conv.to_unit(y))
    if name == "input":
        return conv.to_unit(y).clamp(0, 1)
    if name in ("glossiness",):
        return conv.to_unit(y).clamp(0, 1).expand(-1, 3, -1, -1)
    if name in ("normals", "view_vector"):
        return conv.to_unit(conv.unit_vectors(y)).clamp(0, 1)
    if name == "uv":
        return conv.texture_coords(y).clamp(0, 1)
    if name == "segmentation":
        return conv.to_unit(y).clamp(0, 1)
    if name == "embedding":  # the first three channels of the material embedding as RGB (zeros if fewer)
        y = y[:, :3]
        if y.shape[1] < 3:
            y = torch.cat([y, y.new_zeros(y.shape[0], 3 - y.shape[1], *y.shape[2:])], 1)
        return conv.to_unit(y).clamp(0, 1)
    if name == "envmap":
        return tone_map(conv.env_radiance(y))
    raise ValueError(name)
