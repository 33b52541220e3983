"""Two steps of the Blender evaluation set (scripts/blender-scenes.sh runs both):

    python convert.py textures --out TEX_DIR [TAG=]SRC...   # JPEG/PNG photos and GIMP .pat patterns -> sRGB PNG tiles
    python convert.py scenes RAW_DIR --out SCENES_DIR # Blender's raw renders -> picker scene folders

The scene folders are what `picker eval` reads (the same files as `picker synth` writes, where it
matters): image.png, material_id.png (16-bit), scene.json (materials, camera), the render elements
as EXR (diffuse_albedo, specular_albedo, glossiness, normals, view_vector, uv, segmentation,
envmap, depth) and materials/<id>/texture.exr for textured materials.

Needs numpy, Pillow and OpenEXR (pip).
"""

import argparse
import json
import math
import os
import struct
import sys

import numpy as np
from PIL import Image

MAX_TILE = 512


# ---------------------------------------------------------------------------------------------
# textures


def read_pat(path):
    """A GIMP pattern (.pat): big-endian header (size, version, width, height, bytes per pixel,
    'GPAT', name) followed by the raw pixels."""
    with open(path, "rb") as f:
        data = f.read()
    if len(data) < 24:
        raise ValueError(f"{path}: truncated GIMP pattern")
    header_size, version, w, h, bpp = struct.unpack(">5I", data[:20])
    if data[20:24] != b"GPAT" or version != 1 or bpp not in (1, 2, 3, 4) or w == 0 or h == 0:
        raise ValueError(f"{path}: not a GIMP pattern (version {version}, {bpp} bytes per pixel)")
    px = np.frombuffer(data[header_size:header_size + w * h * bpp], dtype=np.uint8)
    if px.size != w * h * bpp:
        raise ValueError(f"{path}: truncated pixel data")
    px = px.reshape(h, w, bpp)
    if bpp in (1, 2):
        px = np.repeat(px[:, :, :1], 3, axis=2)
    return Image.fromarray(np.ascontiguousarray(px[:, :, :3]), "RGB")


def cmd_textures(a):
    os.makedirs(a.out, exist_ok=True)
    n = 0
    for spec in a.src:
        tag, src = spec.split("=", 1) if "=" in spec else (None, spec)
        tag = tag or os.path.basename(os.path.normpath(src))
        for root, _dirs, files in os.walk(src):
            for f in sorted(files):
                p = os.path.join(root, f)
                ext = f.rsplit(".", 1)[-1].lower()
                try:
                    if ext == "pat":
                        im = read_pat(p)
                    elif ext in ("jpg", "jpeg", "png"):
                        im = Image.open(p).convert("RGB")
                    else:
                        continue
                except Exception as e:  # noqa: BLE001 - report and skip one bad file
                    print(f"convert textures: skipping {p}: {e}", file=sys.stderr)
                    continue
                if min(im.size) < 16:
                    continue
                s = MAX_TILE / max(im.size)
                if s < 1:
                    im = im.resize((max(1, round(im.width * s)), max(1, round(im.height * s))),
                                   Image.LANCZOS)
                name = f"{tag}__{os.path.relpath(p, src).replace(os.sep, '_').rsplit('.', 1)[0]}.png"
                im.save(os.path.join(a.out, name))
                n += 1
    print(f"convert textures: {n} tiles in {a.out}")


# ---------------------------------------------------------------------------------------------
# scenes


def read_multilayer(path):
    import OpenEXR

    with OpenEXR.File(path, separate_channels=True) as f:
        chans = f.channels()
        return {k: np.asarray(v.pixels, dtype=np.float32) for k, v in chans.items()}


def pick(ch, layer, names):
    """Planes of one Blender pass: 'ViewLayer.<layer>.<name>' (or without the view layer prefix)."""
    out = []
    for n in names:
        for key in (f"ViewLayer.{layer}.{n}", f"{layer}.{n}", n if layer == "" else None):
            if key and key in ch:
                out.append(ch[key])
                break
        else:
            raise KeyError(f"no channel {layer}.{n} (have {sorted(ch)[:12]}...)")
    return np.stack(out, axis=0)


# Set by `scenes --half`: EXRs are written as 16-bit floats (small fixtures).
EXR_DTYPE = np.float32


def write_exr(path, planes):
    """planes: [C, H, W] float32, C = 1 (channel Y) or 3 (R, G, B); written atomically, as
    `EXR_DTYPE` (float32, or float16 with `scenes --half`)."""
    import OpenEXR

    planes = np.asarray(planes, dtype=np.float32)
    if EXR_DTYPE == np.float16:
        planes = np.clip(planes, -65504.0, 65504.0).astype(np.float16)
    if planes.shape[0] == 1:
        chans = {"Y": np.ascontiguousarray(planes[0])}
    else:
        chans = {c: np.ascontiguousarray(planes[i]) for i, c in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    tmp = path + ".tmp.exr"
    with OpenEXR.File(header, chans) as f:
        f.write(tmp)
    os.replace(tmp, path)


def write_png(path, arr):
    """uint8 [H, W, 3] (sRGB) or uint16 [H, W] (grey), written atomically."""
    tmp = path + ".tmp.png"
    Image.fromarray(arr).save(tmp)
    os.replace(tmp, path)


def srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_decode(v):
    return np.where(v <= 0.04045, v / 12.92, np.power((v + 0.055) / 1.055, 2.4))


def aces_fit(x):
    """A filmic tone curve (the widely used rational fit of the ACES RRT+ODT by K. Narkowicz)."""
    return np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def convert_scene(raw, out, rng):
    with open(os.path.join(raw, "meta.json")) as fh:
        meta = json.load(fh)
    ch = read_multilayer(os.path.join(raw, "render.exr"))
    h, w = meta["height"], meta["width"]
    combined = pick(ch, "Combined", "RGB")
    diff = pick(ch, "DiffCol", "RGB")
    normal_w = pick(ch, "Normal", "XYZ")
    uvp = pick(ch, "UV", "UVA") if "ViewLayer.UV.A" in ch else pick(ch, "UV", "UV")
    index = pick(ch, "IndexMA", "X")[0]
    depth = pick(ch, "Depth", "Z")[0]
    assert combined.shape[1:] == (h, w), combined.shape
    ids = np.rint(index).astype(np.int64)
    sky = ids <= 0
    mats = {m["id"]: m for m in meta["materials"]}

    # Camera frame: columns of R are the camera's x, y, z axes in the world.
    R = np.array(meta["camera"]["rotation"], dtype=np.float64).T
    n = np.einsum("ij,jhw->ihw", R.T, normal_w.astype(np.float64))
    n /= np.maximum(np.linalg.norm(n, axis=0, keepdims=True), 1e-8)
    # Per-pixel direction towards the camera (camera looks down -z).
    fov = math.radians(meta["camera"]["fov_y_deg"])
    f = h / 2 / math.tan(fov / 2)
    xs = (np.arange(w) + 0.5 - w / 2) / f
    ys = -(np.arange(h) + 0.5 - h / 2) / f
    ray = np.stack([np.broadcast_to(xs[None, :], (h, w)), np.broadcast_to(ys[:, None], (h, w)),
                    -np.ones((h, w))])
    view = -ray / np.linalg.norm(ray, axis=0, keepdims=True)
    n[:, sky] = view[:, sky]
    # Normals facing away from the camera (edge pixels averaging two faces) are turned towards it.
    back = (n * view).sum(0) < 0
    n[:, back] -= 2 * (n * view).sum(0)[back] * view[:, back]

    # Exposure as picker synth: log-average luminance -> a key of 0.18 (randomised 0.12–0.25),
    # then a tone curve drawn per scene: sRGB clip or a filmic curve.
    lum = 0.2126 * combined[0] + 0.7152 * combined[1] + 0.0722 * combined[2]
    key = rng.uniform(0.12, 0.25)
    exposure = key / math.exp(float(np.mean(np.log(np.maximum(lum, 1e-4)))))
    tone = "srgb_clip" if rng.random() < 0.5 else "filmic"
    lin = combined * exposure
    shown = srgb_encode(lin) if tone == "srgb_clip" else srgb_encode(aces_fit(lin * 1.6))
    img8 = np.rint(np.clip(shown, 0, 1) * 255).astype(np.uint8).transpose(1, 2, 0)

    os.makedirs(out, exist_ok=True)
    write_png(os.path.join(out, "image.png"), img8)
    write_exr(os.path.join(out, "image.exr"), lin)

    spec = np.zeros((3, h, w), np.float32)
    gloss = np.zeros((1, h, w), np.float32)
    seg = np.zeros((3, h, w), np.float32)
    uvt = np.zeros((3, h, w), np.float32)
    scene_mats = []
    for mid, m in mats.items():
        sel = ids == mid
        # Principled specular s -> F0 = 0.08 s; GGX alpha = roughness^2 -> Blinn-Phong exponent
        # 2/alpha^2 - 2, about 4x the exponent of the mirror-vector Phong lobe picker uses.
        f0 = 0.08 * m["specular"]
        alpha = max(m["roughness"] ** 2, 1e-3)
        n_phong = max((2.0 / alpha ** 2 - 2.0) / 4.0, 1.0)
        g = min(max(math.log2(n_phong) / 13.0, 0.0), 1.0)
        spec[:, sel] = f0
        gloss[0, sel] = g
        entry = {"id": mid, "name": m["name"], "textured": m["textured"],
                 "specular_albedo": [f0] * 3, "phong_exponent": n_phong, "glossiness": g,
                 "principled": {"roughness": m["roughness"], "specular": m["specular"]}}
        if m["textured"]:
            tile = np.asarray(Image.open(m["texture"]).convert("RGB"), dtype=np.float32) / 255.0
            tex = srgb_decode(tile).transpose(2, 0, 1)
            mean = tex.reshape(3, -1).mean(1)
            md = os.path.join(out, "materials", str(mid))
            os.makedirs(md, exist_ok=True)
            write_exr(os.path.join(md, "texture.exr"), tex)
            write_png(os.path.join(md, "texture.png"), (np.asarray(Image.open(m["texture"]).convert("RGB"))))
            entry["family"] = "blender:" + os.path.basename(m["texture"]).split("__")[0]
            entry["texture_source"] = os.path.basename(m["texture"])
            entry["tiling"] = m.get("tiling")
            # Blender's UV (0,0) is the image's bottom-left corner; picker's v = 0 is its top row.
            u = uvp[0] - np.floor(uvp[0])
            v = (1.0 - uvp[1]) - np.floor(1.0 - uvp[1])
            uvt[0, sel], uvt[1, sel], uvt[2, sel] = u[sel], v[sel], 1.0
            rho = mean
        else:
            rho = np.array(m["diffuse_colour"], np.float32)
            entry["family"] = "single_colour"
            entry["diffuse_colour"] = [float(c) for c in rho]
        seg[:, sel] = ((rho + f0) / 2)[:, None]
        scene_mats.append(entry)

    diff[:, sky] = 0.0
    write_exr(os.path.join(out, "diffuse_albedo.exr"), diff)
    write_exr(os.path.join(out, "specular_albedo.exr"), spec)
    write_exr(os.path.join(out, "glossiness.exr"), gloss)
    write_exr(os.path.join(out, "normals.exr"), n.astype(np.float32))
    write_exr(os.path.join(out, "view_vector.exr"), view.astype(np.float32))
    write_exr(os.path.join(out, "uv.exr"), uvt)
    write_exr(os.path.join(out, "segmentation.exr"), seg)
    write_exr(os.path.join(out, "depth.exr"), np.where(sky, 0.0, depth)[None].astype(np.float32))
    for name, arr in (("diffuse_albedo", srgb_encode(diff)), ("normals", (n + 1) / 2),
                      ("segmentation", seg)):
        write_png(os.path.join(out, f"{name}.png"),
                  np.rint(np.clip(arr, 0, 1) * 255).astype(np.uint8).transpose(1, 2, 0))
    write_png(os.path.join(out, "material_id.png"), np.clip(ids, 0, 65535).astype(np.uint16))

    env = read_multilayer(os.path.join(raw, "env.exr"))
    env = pick(env, "Combined", "RGB") * exposure
    write_exr(os.path.join(out, "envmap.exr"), env)

    scene = {
        "generator": "blender-cycles", "generator_version": "1",
        "blender": meta["blender"], "samples": meta["samples"],
        "index": meta["index"], "seed": meta["seed"], "width": w, "height": h,
        "exposure": exposure, "tone_curve": tone, "key": key,
        "camera": {"fov_y_deg": meta["camera"]["fov_y_deg"], "position": meta["camera"]["position"],
                   "yaw_deg": meta["camera"]["yaw_deg"], "pitch_deg": meta["camera"]["pitch_deg"],
                   "roll_deg": meta["camera"]["roll_deg"]},
        "room_m": meta["room_m"], "window": meta["window"], "lights": meta["lights"],
        "sky": meta["sky"], "materials": scene_mats,
        "notes": "specular albedo and glossiness are the Principled BSDF's specular and roughness "
                 "converted to Phong (approximate); diffuse albedo is Cycles' DiffCol pass",
    }
    tmp = os.path.join(out, "scene.json.tmp")
    with open(tmp, "w") as fh:
        json.dump(scene, fh, indent=1)
    os.replace(tmp, os.path.join(out, "scene.json"))


def cmd_scenes(a):
    global EXR_DTYPE
    EXR_DTYPE = np.float16 if a.half else np.float32
    raws = sorted(d for d in os.listdir(a.raw) if os.path.exists(os.path.join(a.raw, d, "meta.json")))
    if not raws:
        raise SystemExit(f"convert scenes: no rendered scenes in {a.raw}")
    for d in raws:
        out = os.path.join(a.out, d)
        if os.path.exists(os.path.join(out, "scene.json")) and not a.force:
            continue
        idx = int(d.split("_")[-1])
        convert_scene(os.path.join(a.raw, d), out, np.random.default_rng(a.seed * 7919 + idx))
        print(f"convert scenes: {out}")


def main():
    p = argparse.ArgumentParser(prog="convert.py")
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("textures")
    t.add_argument("--out", required=True)
    t.add_argument("src", nargs="+", help="[TAG=]DIR; TAG (default: the folder name) prefixes the tiles' names")
    s = sub.add_parser("scenes")
    s.add_argument("raw")
    s.add_argument("--out", required=True)
    s.add_argument("--seed", type=int, default=31337)
    s.add_argument("--force", action="store_true")
    s.add_argument("--half", action="store_true", help="write 16-bit float EXRs (small fixtures)")
    a = p.parse_args()
    {"textures": cmd_textures, "scenes": cmd_scenes}[a.cmd](a)


if __name__ == "__main__":
    main()
