"""Training data held on the training device: scene packs, batched sampling on the GPU, photometric augmentation.

The reader of :mod:`training.synth_data` decodes seven EXRs per IRN sample in Python and prepares each sample on
the CPU: fine for a 2-core CPU run, far too slow to feed a GPU (it measured ~9 IRN samples/s per core). This
module keeps every training scene in the device's memory and makes a whole batch there with a few batched
tensor operations, so a GPU run is bound by the networks, not by the data.

**Packs.** ``python -m training.pack SYNTH_DIR --out PACK_DIR`` turns a ``picker synth`` output folder into one
folder of ``.npy`` arrays (every element of every scene, ``image`` as the 8-bit sRGB values of ``image.png``,
``surface`` as uint8, the element values as written by synth in float16) and a ``meta.json``; a 120×160 scene
takes 0.8 MB instead of synth's 3.2 MB of EXRs and PNGs, so tens of thousands of scenes fit a disk and
a GPU. :class:`DeviceData` reads packs and synth folders alike.

**Same samples as the CPU reader.** Sample k of a run is the one :class:`training.synth_data.SynthDataset`
gives: the same scene permutation, the same crop and mirror drawn from ``default_rng([seed, 2**32 + k])``,
the same reduction, envmap resampling and target encoding (:func:`training.synth_data.prepare`), done on whole
batches. The only differences are the float16 storage of element values (|error| ≤ 2⁻¹¹ relative) and the
order of clamping and reduction; ``training/test_train.py`` checks the batches against the CPU reader.
"""

import json
import os

import numpy as np
import torch
import torch.nn.functional as F

from training import synth_data as sd

PACK_FORMAT = "picker-pack 1"
"""``meta.json`` ``format`` of the packs this module writes and reads."""

ELEMENTS = ("diffuse_albedo", "specular_albedo", "normals", "glossiness", "view_vector", "uv", "segmentation",
            "envmap")
"""Every element a pack holds (besides ``image`` and ``surface``)."""

NET_ELEMENTS = {"irn": sd.IRN_ELEMENTS, "msn": ("segmentation",), "envmap": ("envmap",)}
"""The elements each net trains on."""


def _load_all(scene_dir):
    r = sd.load_scene(scene_dir, "irn")
    for name in ("segmentation", "envmap"):
        r[name] = sd.read_exr(os.path.join(scene_dir, f"{name}.exr"))
    return r


def _pack_arrays(r, names=ELEMENTS):
    out = {"image": np.clip(np.rint(r["image"] * 255.0), 0, 255).astype(np.uint8),
           "surface": r["surface"].astype(np.uint8)}
    for name in names:
        a = r[name]
        if not np.isfinite(a).all():
            raise ValueError(f"{name} holds non-finite values")
        out[name] = np.clip(a, -65504.0, 65504.0).astype(np.float16)
    return out


def pack(synth_dir, out_dir, workers=1):
    """Packs every scene of ``synth_dir`` (a ``picker synth --out`` folder) into ``out_dir``; returns its meta.

    All scenes must have one size. Written to ``out_dir + ".tmp"`` first and renamed, so an interrupted pack
    leaves no half-written pack."""
    scenes = sd.list_scenes([synth_dir])
    infos = [sd.scene_info(s) for s in scenes]
    sizes = {(h, w) for _, _, h, w in infos}
    if len(sizes) != 1:
        raise ValueError(f"{synth_dir}: scenes of several sizes {sorted(sizes)}; pack each size on its own")
    (h, w), n = sizes.pop(), len(scenes)
    tmp = out_dir.rstrip("/") + ".tmp"
    if os.path.exists(out_dir):
        raise FileExistsError(f"{out_dir} exists")
    os.makedirs(tmp, exist_ok=True)
    first = _pack_one(scenes[0])
    arrays = {name: np.lib.format.open_memmap(os.path.join(tmp, f"{name}.npy"), mode="w+", dtype=a.dtype,
                                              shape=(n, *a.shape)) for name, a in first.items()}

    def put(i, packed):
        for name, a in packed.items():
            if a.shape != arrays[name].shape[1:]:
                raise ValueError(f"{scenes[i]}: {name} is {a.shape}, expected {arrays[name].shape[1:]}")
            arrays[name][i] = a

    put(0, first)
    if workers > 1 and n > 1:
        from concurrent.futures import ProcessPoolExecutor  # noqa: PLC0415

        with ProcessPoolExecutor(workers) as ex:
            for i, packed in enumerate(ex.map(_pack_one, scenes[1:], chunksize=16), start=1):
                put(i, packed)
    else:
        for i in range(1, n):
            put(i, _pack_one(scenes[i]))
    for a in arrays.values():
        a.flush()
    del arrays
    meta = {"format": PACK_FORMAT, "height": h, "width": w, "count": n,
            "seeds": [s for s, _, _, _ in infos], "indices": [i for _, i, _, _ in infos],
            "scenes": [os.path.basename(s) for s in scenes]}
    with open(os.path.join(tmp, "meta.json"), "w") as f:
        json.dump(meta, f)
    os.replace(tmp, out_dir)
    return meta


def _pack_one(scene_dir):
    try:
        return _pack_arrays(_load_all(scene_dir))
    except Exception as e:  # name the scene: the pool would only say which call failed
        raise ValueError(f"{scene_dir}: {e}") from e


def is_pack(path):
    """True when ``path`` is a pack folder (holds a ``meta.json`` of :data:`PACK_FORMAT`)."""
    p = os.path.join(path, "meta.json")
    if not os.path.isfile(p):
        return False
    with open(p) as f:
        return json.load(f).get("format") == PACK_FORMAT


def read_pack_meta(path):
    with open(os.path.join(path, "meta.json")) as f:
        meta = json.load(f)
    if meta.get("format") != PACK_FORMAT:
        raise ValueError(f"{path}/meta.json: format {meta.get('format')!r}, expected {PACK_FORMAT!r}")
    return meta


class _Group:
    """The scenes of one source (a pack or a synth folder), one size, as device tensors of raw values."""

    def __init__(self, tensors, height, width, seeds):
        self.t, self.height, self.width, self.seeds = tensors, height, width, seeds

    def __len__(self):
        return len(self.seeds)


def _group_from_pack(path, names, device):
    meta = read_pack_meta(path)
    t = {}
    for name in ("image", "surface") + tuple(names):
        f = os.path.join(path, f"{name}.npy")
        if not os.path.isfile(f):
            raise FileNotFoundError(f"{path}: no {name}.npy in this pack")
        a = np.load(f, mmap_mode="r")
        if a.shape[0] != meta["count"]:
            raise ValueError(f"{f}: {a.shape[0]} scenes, meta.json says {meta['count']}")
        t[name] = torch.from_numpy(np.array(a)).to(device)
    return _Group(t, meta["height"], meta["width"], list(meta["seeds"]))


def _group_from_synth(scenes, net, size, seeds, device):
    """The scenes (folders, all of ``size``) of one group, read for ``net`` alone."""
    arrays = {}
    for s in scenes:
        for name, a in _pack_arrays(sd.load_scene(s, net), NET_ELEMENTS[net]).items():
            arrays.setdefault(name, []).append(a)
    t = {name: torch.from_numpy(np.stack(v)).to(device) for name, v in arrays.items()}
    return _Group(t, size[0], size[1], seeds)


def _reduce(raw, k):
    """:func:`training.synth_data.reduce_scene` on batched tensors [B, C, H, W]."""
    if k == 1:
        return raw
    out = {}
    for name, a in raw.items():
        h, w = a.shape[-2] // k * k, a.shape[-1] // k * k
        if name == "envmap":
            out[name] = a
            continue
        a = a[..., :h, :w]
        if name in ("image", "diffuse_albedo", "specular_albedo", "glossiness"):
            out[name] = F.avg_pool2d(a, k)
        elif name in ("normals", "view_vector"):
            v = F.avg_pool2d(a, k)
            out[name] = v / torch.linalg.vector_norm(v, dim=1, keepdim=True).clamp_min(1e-12)
        elif name in ("uv", "segmentation"):
            out[name] = a[..., k // 2::k, k // 2::k]
        elif name in ("surface", "textured"):
            out[name] = -F.max_pool2d(-a, k)
        else:
            raise ValueError(name)
    return out


class DeviceData:
    """All training scenes of ``sources`` (pack folders and ``picker synth`` folders) on ``device``, sampled as
    :class:`training.synth_data.SynthDataset` samples them (same arguments), a whole batch at a time."""

    def __init__(self, sources, net, seed, device, flip=True, crop="random", shuffle=True):
        if net not in NET_ELEMENTS:
            raise ValueError(f"no synth targets for net {net!r}")
        self.net, self.seed, self.flip, self.crop, self.shuffle = net, int(seed), flip, crop, shuffle
        self.device = torch.device(device)
        self.names = NET_ELEMENTS[net]
        self.groups, self.where = [], []  # where[i] = (group, index in group) of scene i
        self.add(sources)

    def add(self, sources):
        """Appends the scenes of more ``sources`` (after those already held). The scene order, and so the
        permutations of later sample numbers, are those of a reader made with all the sources at once."""
        for src in sources:
            src = os.fspath(src)
            if is_pack(src):
                group = _group_from_pack(src, self.names, self.device)
                self.where.extend((len(self.groups), j) for j in range(len(group)))
                self.groups.append(group)
                continue
            # A synth folder: one group per scene size; the scenes keep list_scenes' order.
            by_size, order = {}, []
            for s in sd.list_scenes([src]):
                scene_seed, _, h, w = sd.scene_info(s)
                scenes, seeds = by_size.setdefault((h, w), ([], []))
                order.append(((h, w), len(scenes)))
                scenes.append(s)
                seeds.append(scene_seed)
            index = {}
            for size, (scenes, seeds) in by_size.items():
                index[size] = len(self.groups)
                self.groups.append(_group_from_synth(scenes, self.net, size, seeds, self.device))
            self.where.extend((index[size], j) for size, j in order)
        if not self.where:
            raise ValueError("no scenes")
        sizes = [(self.groups[g].height, self.groups[g].width) for g, _ in self.where]
        # The scene order and permutations of the CPU reader (it needs only the scene count and sizes).
        self.order = sd.SynthDataset([f"scene {i}" for i in range(len(sizes))], self.net, self.seed,
                                     size_of=None, flip=self.flip, crop=self.crop, shuffle=self.shuffle,
                                     sizes=sizes)

    def __len__(self):
        return len(self.where)

    def eligible(self, size):
        """As :meth:`training.synth_data.SynthDataset.eligible`: raises ValueError when no scene is that big."""
        return self.order.eligible(size)

    def batch(self, ks, size):
        """The batch of global sample numbers ``ks`` at training size ``size`` = (H, W): a dict of float32
        device tensors, as ``default_collate`` of the CPU reader's samples."""
        h, w = size
        n = len(ks)
        draws = {}
        for pos, k in enumerate(ks):
            i = self.order.scene_index(int(k), tuple(size))
            g, j = self.where[i]
            grp = self.groups[g]
            kf = sd.reduction_factor(grp.height, grp.width, h, w)
            hr, wr = grp.height // kf, grp.width // kf
            rng = np.random.default_rng([self.seed, (1 << 32) + int(k)])
            if self.crop == "random":
                top, left = int(rng.integers(0, hr - h + 1)), int(rng.integers(0, wr - w + 1))
            else:
                top, left = (hr - h) // 2, (wr - w) // 2
            mirror = bool(self.flip and rng.random() < 0.5)
            draws.setdefault(g, []).append((pos, j, top, left, mirror))
        out = {}
        dev = self.device
        for g, items in draws.items():
            grp = self.groups[g]
            kf = sd.reduction_factor(grp.height, grp.width, h, w)
            pos = torch.tensor([it[0] for it in items], device=dev)
            idx = torch.tensor([it[1] for it in items], device=dev)
            top = torch.tensor([it[2] for it in items], device=dev)
            left = torch.tensor([it[3] for it in items], device=dev)
            mirror = torch.tensor([it[4] for it in items], device=dev)
            raw = {}
            for name, t in grp.t.items():
                a = t.index_select(0, idx).float()
                raw[name] = a / 255.0 if name == "image" else a
            if "uv" in raw:
                raw["textured"] = raw["surface"] * (raw["uv"][:, 2:3] >= 0.5)
            r = _reduce(raw, kf)
            ar_h, ar_w = torch.arange(h, device=dev), torch.arange(w, device=dev)
            rows = top[:, None] + ar_h[None]                                         # [b, h]
            cols = torch.where(mirror[:, None], left[:, None] + (w - 1 - ar_w)[None], left[:, None] + ar_w[None])
            sample = {}
            for name, a in r.items():
                if name == "envmap":
                    ew = a.shape[-1]
                    ec = torch.where(mirror[:, None], (ew - 1 - torch.arange(ew, device=dev))[None],
                                     torch.arange(ew, device=dev)[None])
                    a = a.gather(3, ec[:, None, None, :].expand(-1, a.shape[1], a.shape[2], -1))
                    sample[name] = sd.resize_envmap(a, (max(1, h // 8), max(1, w // 8)))
                    continue
                b, c = a.shape[:2]
                a = a.gather(2, rows[:, None, :, None].expand(b, c, h, a.shape[-1]))
                a = a.gather(3, cols[:, None, None, :].expand(b, c, h, w))
                if name in ("normals", "view_vector"):
                    sign = torch.ones(b, 3, 1, 1, device=dev)
                    sign[:, 0, 0, 0] = torch.where(mirror, -1.0, 1.0)
                    a = a * sign
                sample[name] = a
            t = sd.encode_targets(sample)
            t["input"] = t.pop("image")
            for name, a in t.items():
                if name not in out:
                    out[name] = torch.empty((n, *a.shape[1:]), dtype=torch.float32, device=dev)
                out[name][pos] = a
        return out


def augment_photometric(x, seed, step, params):
    """Photometric augmentation of a batch of network inputs ``x`` ([N, 3, H, W], 2·sRGB − 1) in place of the
    camera: with probability ``p`` per sample, an exposure gain (log-uniform in ``exposure``), a white-balance
    gain per channel (log-uniform in [1/(1 + wb), 1 + wb]) and a lens vignetting, all applied in linear light
    with the sRGB clipping a camera does, then Gaussian noise of σ uniform in [0, ``noise``] (sRGB units).
    The vignetting (``vignette`` = v, default 0: none) multiplies by 1 − k·(r/r₀)², k uniform in [0, v],
    r the distance to a centre jittered by up to ±10 % of the image's size, r₀ the half-diagonal: real
    photos darken towards their corners, and a network that takes that fall-off for a change of material
    splits one table into two (the stop-30 real-photo sheets). The targets (albedos, normals,
    segmentation: properties of the surfaces) do not change. Deterministic in (seed, step); with
    ``vignette`` 0 the result is that of the recipes made before it existed, bit for bit.

    Camera effects beyond those (each off by default, drawn after everything above, so the recipes made
    before them are unchanged): ``blur`` = b, a Gaussian blur of σ uniform in [0, b] pixels in linear light
    (lens softness, defocus, resampling); ``tone`` = t, the encoded values raised to γ log-uniform in
    [1/(1 + t), 1 + t] (a camera's tone curve); ``saturation`` = s, a saturation gain uniform in
    [1 − s, 1 + s] around each pixel's grey; ``jpeg`` = [lo, hi], a JPEG round trip at a quality uniform in
    [lo, hi] after the noise (Pillow on the CPU)."""
    n = x.shape[0]
    rng = np.random.default_rng([int(seed), 3 << 32, int(step)])
    p = float(params.get("p", 0.8))
    lo, hi = params.get("exposure", [0.5, 2.0])
    wb = float(params.get("white_balance", 0.15))
    noise = float(params.get("noise", 0.02))
    on = rng.random(n) < p
    gain = np.exp(rng.uniform(np.log(lo), np.log(hi), n))
    balance = np.exp(rng.uniform(-np.log1p(wb), np.log1p(wb), (n, 3)))
    sigma = rng.uniform(0.0, noise, n)
    g = torch.from_numpy(np.where(on[:, None], gain[:, None] * balance, 1.0)).float().to(x.device)
    s = torch.from_numpy(np.where(on, sigma, 0.0)).float().to(x.device)
    gen = torch.Generator(device=x.device).manual_seed(int(rng.integers(0, 2**62)))
    srgb = (x + 1.0) / 2.0
    lin = sd.srgb_decode(srgb.clamp(0.0, 1.0)) * g[:, :, None, None]
    vignette = float(params.get("vignette", 0.0))
    if vignette > 0.0:
        # Drawn after everything the recipes without vignetting draw, so theirs stay as they were.
        k = np.where(on, rng.uniform(0.0, vignette, n), 0.0)
        centre = rng.uniform(-0.1, 0.1, (n, 2))
        h, w = x.shape[2], x.shape[3]
        ys = (torch.arange(h, device=x.device, dtype=torch.float32) + 0.5) / h - 0.5
        xs = (torch.arange(w, device=x.device, dtype=torch.float32) + 0.5) / w - 0.5
        cy = torch.from_numpy(centre[:, 0]).float().to(x.device)[:, None, None]
        cx = torch.from_numpy(centre[:, 1]).float().to(x.device)[:, None, None]
        # Distances in pixels over the half-diagonal.
        r2 = (((ys[None, :, None] - cy) * h) ** 2 + ((xs[None, None, :] - cx) * w) ** 2) / (0.25 * (h * h + w * w))
        fall = 1.0 - torch.from_numpy(k).float().to(x.device)[:, None, None] * r2.clamp(max=1.0)
        lin = lin * fall[:, None, :, :]
    blur = float(params.get("blur", 0.0))
    if blur > 0.0:
        # Drawn after the vignetting's numbers: lens softness, defocus, a photo scaled down and up.
        bs = np.where(on, rng.uniform(0.0, blur, n), 0.0)
        lin = gaussian_blur(lin, bs)
    encoded = sd.srgb_encode(lin)
    tone = float(params.get("tone", 0.0))
    saturation = float(params.get("saturation", 0.0))
    if tone > 0.0 or saturation > 0.0:
        # A camera's own tone curve and colour rendering: a power of the encoded values (γ log-uniform in
        # [1/(1 + tone), 1 + tone]) and a saturation gain around the grey of each pixel.
        gamma = np.where(on, np.exp(rng.uniform(-np.log1p(tone), np.log1p(tone), n)), 1.0)
        sat = np.where(on, rng.uniform(1.0 - saturation, 1.0 + saturation, n), 1.0)
        gm = torch.from_numpy(gamma).float().to(x.device)[:, None, None, None]
        st = torch.from_numpy(sat).float().to(x.device)[:, None, None, None]
        encoded = encoded.clamp(0.0, 1.0) ** gm
        grey = encoded.mean(dim=1, keepdim=True)
        encoded = grey + st * (encoded - grey)
    out = encoded + s[:, None, None, None] * torch.randn(x.shape, generator=gen, device=x.device)
    out = out.clamp(0.0, 1.0)
    jpeg = params.get("jpeg")
    if jpeg:
        # JPEG compression at a quality uniform in [lo, hi], with probability ``p`` again (most real
        # photos are JPEGs: 8×8 blocks, ringing, chroma subsampling).
        qlo, qhi = jpeg
        q = rng.integers(int(qlo), int(qhi) + 1, n)
        out = jpeg_roundtrip(out, np.where(on, q, 0))
    keep = torch.from_numpy(~on).to(x.device)[:, None, None, None]
    return torch.where(keep, x, 2.0 * out - 1.0)


def gaussian_blur(x, sigmas):
    """Each image ``x[i]`` ([N, C, H, W]) blurred by a Gaussian of σ ``sigmas[i]`` pixels (separable, radius
    ⌈3σ⌉, borders reflected, or extended by their edge pixels where the image is not wider than the radius,
    so any size works); σ below 0.05 leaves it as it is."""
    out = x.clone()
    for i, sigma in enumerate(sigmas):
        if sigma < 0.05:
            continue
        r = int(np.ceil(3.0 * sigma))
        t = torch.arange(-r, r + 1, dtype=torch.float32, device=x.device)
        k = torch.exp(-0.5 * (t / float(sigma)) ** 2)
        k = k / k.sum()
        c = x.shape[1]
        mode = "reflect" if r < min(x.shape[2], x.shape[3]) else "replicate"
        img = torch.nn.functional.pad(x[i:i + 1], (r, r, r, r), mode=mode)
        img = torch.nn.functional.conv2d(img, k.view(1, 1, 1, -1).repeat(c, 1, 1, 1), groups=c)
        img = torch.nn.functional.conv2d(img, k.view(1, 1, -1, 1).repeat(c, 1, 1, 1), groups=c)
        out[i] = img[0]
    return out


def jpeg_roundtrip(x, qualities):
    """Each image ``x[i]`` ([N, 3, H, W], values in [0, 1]) encoded as a JPEG of quality ``qualities[i]`` and
    decoded (Pillow, 4:2:0 chroma subsampling); quality 0 leaves the image as it is."""
    import io

    from PIL import Image

    out = x.clone()
    for i, q in enumerate(qualities):
        if q <= 0:
            continue
        a = (x[i].detach().cpu().permute(1, 2, 0).numpy() * 255.0 + 0.5).clip(0, 255).astype(np.uint8)
        buf = io.BytesIO()
        Image.fromarray(a).save(buf, format="JPEG", quality=int(q), subsampling=2)
        buf.seek(0)
        b = np.asarray(Image.open(buf).convert("RGB"), dtype=np.float32) / 255.0
        out[i] = torch.from_numpy(b).permute(2, 0, 1).to(x.device)
    return out


def source_seeds(sources):
    """Sorted distinct generator seeds of the scenes of ``sources`` (packs and synth folders), read from the
    packs' ``meta.json`` and the scenes' ``scene.json`` without loading any image."""
    seeds = set()
    for src in sources:
        src = os.fspath(src)
        if is_pack(src):
            seeds.update(read_pack_meta(src)["seeds"])
        else:
            seeds.update(sd.seeds_of(sd.list_scenes([src])))
    return sorted(seeds)
