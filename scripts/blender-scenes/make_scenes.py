"""Indoor scenes rendered by Blender's Cycles path tracer: an evaluation set from a renderer that is
not ours (global illumination, area lights, a physical sky through a window, Principled BSDF
materials, Cycles' own pixel filtering), for `picker eval`.

Run by scripts/blender-scenes.sh; by hand:

    blender -b --factory-startup -noaudio --python-exit-code 1 -P scripts/blender-scenes/make_scenes.py -- \
        --out RAW_DIR --textures TEX_DIR --seed 31337 --count 40 --size 240x320 --samples 256

TEX_DIR holds the texture tiles as sRGB PNGs (convert.py textures makes it). For each scene this
writes RAW_DIR/scene_NNNNNN/{render.exr (multilayer: Combined, DiffCol, Normal, UV, IndexMA,
Depth), env.exr (the sky alone, equirectangular, in the camera's frame), meta.json}; convert.py turns
that into picker's scene folder (docs: scripts/blender-scenes/README.md).

Blender's Python is the system one; the only module needed beyond bpy is the standard library.
"""

import argparse
import json
import math
import os
import random
import sys
import time

import bpy
from mathutils import Vector

# Approximate linear RGB of black bodies (normalised to max 1), for the room's lamps.
LAMP_COLOURS = {
    2700: (1.0, 0.63, 0.33),
    3000: (1.0, 0.69, 0.42),
    3500: (1.0, 0.76, 0.54),
    4000: (1.0, 0.82, 0.65),
    5000: (1.0, 0.91, 0.84),
    6500: (1.0, 1.0, 1.0),
}


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="make_scenes.py")
    p.add_argument("--out", required=True)
    p.add_argument("--textures", required=True, help="folder of sRGB PNG tiles (convert.py textures)")
    p.add_argument("--seed", type=int, default=31337)
    p.add_argument("--count", type=int, default=40)
    p.add_argument("--start", type=int, default=0, help="first scene index (to resume or split)")
    p.add_argument("--size", default="240x320", help="HxW")
    p.add_argument("--samples", type=int, default=256)
    p.add_argument("--threads", type=int, default=0, help="0: all cores")
    p.add_argument("--pixel-filter", choices=["blackman-harris", "box"], default="blackman-harris",
                   help="Cycles' pixel filter: Blender's default (Blackman-Harris, 1.5 px wide) or a "
                        "1-pixel box (as picker synth's samples)")
    a = p.parse_args(argv)
    h, w = (int(x) for x in a.size.lower().split("x"))
    if h < 8 or w < 8:
        p.error(f"--size {a.size}: at least 8x8")
    a.height, a.width = h, w
    return a


def texture_list(folder):
    out = []
    for root, _dirs, files in os.walk(folder):
        for f in sorted(files):
            if f.endswith(".png"):
                out.append(os.path.join(root, f))
    out.sort()
    if not out:
        raise SystemExit(f"make_scenes: no PNG textures under {folder}")
    return out


def reset(a):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = a.samples
    sc.cycles.use_adaptive_sampling = True
    sc.cycles.adaptive_threshold = 0.01
    sc.cycles.use_denoising = False
    sc.cycles.max_bounces = 6
    sc.cycles.diffuse_bounces = 4
    sc.cycles.glossy_bounces = 4
    sc.cycles.sample_clamp_indirect = 10.0
    sc.cycles.seed = 0
    if a.pixel_filter == "box":
        sc.cycles.pixel_filter_type = "BOX"
        sc.cycles.filter_width = 1.0
    else:
        sc.cycles.pixel_filter_type = "BLACKMAN_HARRIS"
        sc.cycles.filter_width = 1.5
    sc.render.resolution_x = a.width
    sc.render.resolution_y = a.height
    sc.render.resolution_percentage = 100
    sc.render.threads_mode = "FIXED" if a.threads else "AUTO"
    if a.threads:
        sc.render.threads = a.threads
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    vl = sc.view_layers[0]
    vl.use_pass_combined = True
    vl.use_pass_diffuse_color = True
    vl.use_pass_normal = True
    vl.use_pass_uv = True
    vl.use_pass_material_index = True
    vl.use_pass_z = True
    s = sc.render.image_settings
    s.file_format = "OPEN_EXR_MULTILAYER"
    s.color_depth = "32"
    s.exr_codec = "ZIP"
    return sc


def add_mesh(name, verts, faces, uvs, material):
    """A mesh object from world-space vertices, faces (vertex index lists) and per-loop UVs."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], faces)
    me.update()
    layer = me.uv_layers.new(name="UVMap")
    for poly in me.polygons:
        for li in poly.loop_indices:
            layer.data[li].uv = uvs[me.loops[li].vertex_index]
    me.materials.append(material)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


class Tiling:
    """Metric texture mapping of one material: uv = R(angle)·(a, b)/(su, sv) + offset."""

    def __init__(self, rng, size_m, aspect, angle):
        self.su = size_m
        self.sv = size_m * aspect
        self.angle = angle
        self.offset = (rng.random(), rng.random())

    def uv(self, a, b):
        c, s = math.cos(self.angle), math.sin(self.angle)
        x, y = a / self.su, b / self.sv
        return (c * x - s * y + self.offset[0], s * x + c * y + self.offset[1])

    def json(self):
        return {"tile_m": [self.su, self.sv], "angle_deg": math.degrees(self.angle),
                "offset": list(self.offset)}


def quad(name, origin, ax, bx, a0, a1, b0, b1, tiling, material):
    """The rectangle origin + a·ax + b·bx, a ∈ [a0, a1], b ∈ [b0, b1] (ax × bx is its normal)."""
    o, ax, bx = Vector(origin), Vector(ax), Vector(bx)
    corners = [(a0, b0), (a1, b0), (a1, b1), (a0, b1)]
    verts = [o + a * ax + b * bx for a, b in corners]
    uvs = [tiling.uv(a, b) for a, b in corners]
    return add_mesh(name, verts, [[0, 1, 2, 3]], uvs, material)


def make_material(rng, mid, textures, textured):
    mat = bpy.data.materials.new(f"m{mid}")
    mat.use_nodes = True
    mat.pass_index = mid
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    roughness = rng.uniform(0.15, 0.95) if rng.random() < 0.8 else rng.uniform(0.05, 0.2)
    specular = rng.uniform(0.1, 0.7)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Specular"].default_value = specular
    info = {"id": mid, "roughness": roughness, "specular": specular, "textured": textured}
    if textured:
        # A source first (each equally likely: the photographs are few, the patterns many), then a tile.
        groups = sorted({os.path.basename(t).split("__")[0] for t in textures})
        group = groups[rng.randrange(len(groups))]
        tiles = [t for t in textures if os.path.basename(t).split("__")[0] == group]
        path = tiles[rng.randrange(len(tiles))]
        img = bpy.data.images.load(path, check_existing=True)
        img.colorspace_settings.name = "sRGB"
        node = nt.nodes.new("ShaderNodeTexImage")
        node.image = img
        node.interpolation = "Linear"
        node.extension = "REPEAT"
        nt.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
        info["texture"] = path
        info["texture_size"] = [img.size[0], img.size[1]]
    else:
        # A colour drawn in HSV, linear albedo 0.03–0.85.
        hsv = (rng.random(), rng.uniform(0.0, 0.8), rng.uniform(0.2, 0.92))
        import colorsys

        srgb = colorsys.hsv_to_rgb(*hsv)
        lin = [((c + 0.055) / 1.055) ** 2.4 if c > 0.04045 else c / 12.92 for c in srgb]
        bsdf.inputs["Base Color"].default_value = (*lin, 1.0)
        info["diffuse_colour"] = lin
    return mat, info


def make_world(rng):
    world = bpy.data.worlds.new("sky")
    bpy.context.scene.world = world
    world.use_nodes = True
    nt = world.node_tree
    bg = nt.nodes["Background"]
    sky = nt.nodes.new("ShaderNodeTexSky")
    kind = rng.choice(["NISHITA", "NISHITA", "HOSEK_WILKIE", "PREETHAM"])
    sky.sky_type = kind
    elevation = math.radians(rng.uniform(4.0, 65.0))
    rotation = rng.uniform(0.0, 2.0 * math.pi)
    if kind == "NISHITA":
        sky.sun_elevation = elevation
        sky.sun_rotation = rotation
        sky.air_density = rng.uniform(0.5, 3.0)
        sky.dust_density = rng.uniform(0.0, 5.0)
        sky.ozone_density = rng.uniform(0.5, 2.0)
        sky.sun_intensity = rng.uniform(0.3, 1.0)
        strength = rng.uniform(0.05, 0.4)
    else:
        d = (math.cos(elevation) * math.sin(rotation), -math.cos(elevation) * math.cos(rotation),
             math.sin(elevation))
        sky.sun_direction = d
        sky.turbidity = rng.uniform(2.0, 8.0)
        if kind == "HOSEK_WILKIE":
            sky.ground_albedo = rng.uniform(0.1, 0.5)
        strength = rng.uniform(0.2, 1.2)
    nt.links.new(sky.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = strength
    return {"type": kind.lower(), "sun_elevation_deg": math.degrees(elevation),
            "sun_rotation_deg": math.degrees(rotation), "strength": strength}


def build_scene(a, rng, textures, index):
    sc = reset(a)
    W, D, H = rng.uniform(3.0, 7.0), rng.uniform(3.0, 7.0), rng.uniform(2.4, 3.2)
    mats = []

    def new_material(name, textured):
        mid = len(mats) + 1
        mat, info = make_material(rng, mid, textures, textured)
        info["name"] = name
        mats.append(info)
        return mat, info

    def tiling_for(info, vertical):
        if not info["textured"]:
            return Tiling(rng, 1.0, 1.0, 0.0)
        w, h = info["texture_size"]
        size = math.exp(rng.uniform(math.log(0.25), math.log(2.0)))
        angle = rng.choice([0.0, math.pi / 2]) if vertical else rng.uniform(0, 2 * math.pi)
        t = Tiling(rng, size, h / max(w, 1), angle)
        info["tiling"] = t.json()
        return t

    # Floor, ceiling, walls: textured with probability 0.8 / 0.4 / 0.7.
    floor_m, floor_i = new_material("floor", rng.random() < 0.8)
    ceil_m, ceil_i = new_material("ceiling", rng.random() < 0.4)
    wall_m, wall_i = new_material("walls", rng.random() < 0.7)
    ft, ct, wt = tiling_for(floor_i, False), tiling_for(ceil_i, False), tiling_for(wall_i, True)
    quad("floor", (0, 0, 0), (1, 0, 0), (0, 1, 0), 0, W, 0, D, ft, floor_m)
    quad("ceiling", (0, 0, H), (1, 0, 0), (0, -1, 0), 0, W, -D, 0, ct, ceil_m)
    # Walls: (origin, horizontal axis, length), each facing into the room; one has a window.
    walls = [((0, 0, 0), (1, 0, 0), W), ((W, D, 0), (-1, 0, 0), W),
             ((0, D, 0), (0, -1, 0), D), ((W, 0, 0), (0, 1, 0), D)]
    win_wall = rng.randrange(4)
    window = None
    along = 0.0
    for k, (o, ax, length) in enumerate(walls):
        up = (0, 0, 1)
        if k == win_wall and rng.random() < 0.85:
            ww = rng.uniform(0.8, min(2.2, length - 0.6))
            wh = rng.uniform(0.8, min(1.6, H - 1.0))
            wx0 = rng.uniform(0.3, length - ww - 0.3)
            wz0 = rng.uniform(0.5, H - wh - 0.2)
            window = {"wall": k, "x": [wx0, wx0 + ww], "z": [wz0, wz0 + wh]}
            parts = [(0, wx0, 0, H), (wx0 + ww, length, 0, H), (wx0, wx0 + ww, 0, wz0),
                     (wx0, wx0 + ww, wz0 + wh, H)]
        else:
            parts = [(0, length, 0, H)]
        for j, (a0, a1, b0, b1) in enumerate(parts):
            # Continuous texture along the walls: each wall's a starts where the last one ended.
            quad(f"wall{k}_{j}", o, ax, up, a0, a1, b0, b1, _shifted(wt, along), wall_m)
        along += length

    # Camera: near one wall, facing into the room (±35° off its far side), 1.0–1.8 m high.
    side = rng.randrange(4)
    back = rng.uniform(0.4, 1.2)
    if side == 0:  # near y = 0, looking towards +y
        cam_pos = Vector((rng.uniform(0.5, W - 0.5), back, 0))
    elif side == 1:  # near y = D, looking towards -y
        cam_pos = Vector((rng.uniform(0.5, W - 0.5), D - back, 0))
    elif side == 2:  # near x = 0, looking towards +x
        cam_pos = Vector((back, rng.uniform(0.5, D - 0.5), 0))
    else:  # near x = W, looking towards -x
        cam_pos = Vector((W - back, rng.uniform(0.5, D - 0.5), 0))
    cam_pos.z = rng.uniform(1.0, 1.8)
    # Blender's camera with rotation (90°, 0, yaw) looks along (-sin yaw, cos yaw, 0).
    facing = {0: 0.0, 1: math.pi, 2: -math.pi / 2, 3: math.pi / 2}[side]
    yaw = facing + math.radians(rng.uniform(-35.0, 35.0))
    pitch = math.radians(rng.uniform(-30.0, 10.0))
    roll = math.radians(rng.uniform(-3.0, 3.0))
    fov_y = rng.uniform(45.0, 75.0)

    # Furniture: boxes on the floor, each with its own material, not around the camera.
    boxes = []
    for b in range(rng.randrange(1, 5)):
        for _try in range(20):
            bw, bd, bh = rng.uniform(0.4, 1.6), rng.uniform(0.4, 1.2), rng.uniform(0.3, 1.2)
            x0, y0 = rng.uniform(0.1, max(0.11, W - bw - 0.1)), rng.uniform(0.1, max(0.11, D - bd - 0.1))
            cx, cy = x0 + bw / 2, y0 + bd / 2
            ahead = (cx - cam_pos.x) * -math.sin(yaw) + (cy - cam_pos.y) * math.cos(yaw)
            if math.hypot(cx - cam_pos.x, cy - cam_pos.y) > 1.0 + max(bw, bd) / 2 and ahead > 0.5:
                break
        else:
            continue
        m, info = new_material(f"box {b + 1}", rng.random() < 0.6)
        t = tiling_for(info, False)
        x1, y1 = x0 + bw, y0 + bd
        quad(f"box{b}_top", (x0, y0, bh), (1, 0, 0), (0, 1, 0), 0, bw, 0, bd, t, m)
        quad(f"box{b}_s0", (x0, y0, 0), (1, 0, 0), (0, 0, 1), 0, bw, 0, bh, t, m)
        quad(f"box{b}_s1", (x1, y1, 0), (-1, 0, 0), (0, 0, 1), 0, bw, 0, bh, t, m)
        quad(f"box{b}_s2", (x0, y1, 0), (0, -1, 0), (0, 0, 1), 0, bd, 0, bh, t, m)
        quad(f"box{b}_s3", (x1, y0, 0), (0, 1, 0), (0, 0, 1), 0, bd, 0, bh, t, m)
        boxes.append([x0, y0, 0, x1, y1, bh])
    # Sometimes a single-colour ball (smooth, curved: no plane to rectify).
    if rng.random() < 0.5:
        m, info = new_material("ball", False)
        r = rng.uniform(0.15, 0.4)
        bpy.ops.mesh.primitive_uv_sphere_add(radius=r, segments=48, ring_count=24,
                                             location=(rng.uniform(r, W - r), rng.uniform(r, D - r), r))
        ob = bpy.context.active_object
        bpy.ops.object.shade_smooth()
        ob.data.materials.append(m)

    # Lights: 1–3 ceiling area lights (and the sky through the window).
    lights = []
    for li in range(rng.randrange(1, 4)):
        temp = rng.choice(sorted(LAMP_COLOURS))
        ld = bpy.data.lights.new(f"lamp{li}", "AREA")
        ld.shape = "RECTANGLE"
        ld.size, ld.size_y = rng.uniform(0.2, 1.2), rng.uniform(0.2, 1.2)
        ld.energy = rng.uniform(40.0, 400.0)
        ld.color = LAMP_COLOURS[temp]
        lo = bpy.data.objects.new(f"lamp{li}", ld)
        lo.location = (rng.uniform(0.3, W - 0.3), rng.uniform(0.3, D - 0.3), H - 0.02)
        bpy.context.scene.collection.objects.link(lo)
        lights.append({"kind": "area", "kelvin": temp, "watts": ld.energy,
                       "at": list(lo.location), "size": [ld.size, ld.size_y]})
    if rng.random() < 0.4:
        temp = rng.choice(sorted(LAMP_COLOURS))
        ld = bpy.data.lights.new("bulb", "POINT")
        ld.energy = rng.uniform(20.0, 150.0)
        ld.shadow_soft_size = rng.uniform(0.02, 0.2)
        ld.color = LAMP_COLOURS[temp]
        lo = bpy.data.objects.new("bulb", ld)
        lo.location = (rng.uniform(0.3, W - 0.3), rng.uniform(0.3, D - 0.3), rng.uniform(1.2, H - 0.3))
        bpy.context.scene.collection.objects.link(lo)
        lights.append({"kind": "point", "kelvin": temp, "watts": ld.energy, "at": list(lo.location)})
    sky = make_world(rng)

    cd = bpy.data.cameras.new("camera")
    cd.sensor_fit = "VERTICAL"
    cd.sensor_height = 24.0
    cd.lens = 12.0 / math.tan(math.radians(fov_y) / 2)
    cd.clip_start = 0.05
    cam = bpy.data.objects.new("camera", cd)
    cam.location = cam_pos
    cam.rotation_euler = (math.pi / 2 + pitch, roll, yaw)
    bpy.context.scene.collection.objects.link(cam)
    sc.camera = cam
    bpy.context.view_layer.update()
    rot = cam.matrix_world.to_3x3()

    meta = {
        "index": index, "seed": a.seed, "width": a.width, "height": a.height,
        "samples": a.samples, "blender": bpy.app.version_string,
        "room_m": [W, D, H], "window": window, "boxes": boxes, "lights": lights, "sky": sky,
        "camera": {"position": list(cam_pos), "fov_y_deg": fov_y,
                   "yaw_deg": math.degrees(yaw), "pitch_deg": math.degrees(pitch),
                   "roll_deg": math.degrees(roll),
                   # Columns: the camera's x (right), y (up), z (backwards) axes in the world.
                   "rotation": [list(rot.col[0]), list(rot.col[1]), list(rot.col[2])]},
        "materials": mats,
    }
    return sc, cam, meta


def _shifted(t, da):
    """The same tiling moved along its a axis by da metres (walls continue one another)."""
    s = Tiling.__new__(Tiling)
    s.su, s.sv, s.angle = t.su, t.sv, t.angle
    c, si = math.cos(t.angle), math.sin(t.angle)
    x = da / t.su
    s.offset = (t.offset[0] + c * x, t.offset[1] + si * x)
    return s


def render_env(sc, cam, a, path):
    """The sky alone from the camera, equirectangular at 1/8 size (row 0 up, centre ahead)."""
    for ob in sc.objects:
        if ob.type in {"MESH", "LIGHT"}:
            ob.hide_render = True
    cd = cam.data
    cd.type = "PANO"
    cd.cycles.panorama_type = "EQUIRECTANGULAR"
    cd.cycles.latitude_min, cd.cycles.latitude_max = -math.pi / 2, math.pi / 2
    cd.cycles.longitude_min, cd.cycles.longitude_max = -math.pi, math.pi
    sc.render.resolution_x = max(1, a.width // 8)
    sc.render.resolution_y = max(1, a.height // 8)
    sc.cycles.samples = 64
    sc.cycles.use_adaptive_sampling = False
    vl = sc.view_layers[0]
    vl.use_pass_diffuse_color = vl.use_pass_normal = vl.use_pass_uv = False
    vl.use_pass_material_index = vl.use_pass_z = False
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)


def main():
    a = parse_args()
    textures = texture_list(a.textures)
    os.makedirs(a.out, exist_ok=True)
    for i in range(a.start, a.start + a.count):
        d = os.path.join(a.out, f"scene_{i:06d}")
        if os.path.exists(os.path.join(d, "meta.json")):
            continue
        os.makedirs(d, exist_ok=True)
        rng = random.Random(a.seed * 1_000_003 + i)
        t0 = time.time()
        sc, cam, meta = build_scene(a, rng, textures, i)
        sc.render.filepath = os.path.join(d, "render.exr")
        bpy.ops.render.render(write_still=True)
        render_env(sc, cam, a, os.path.join(d, "env.exr"))
        meta["render_seconds"] = time.time() - t0
        tmp = os.path.join(d, "meta.json.tmp")
        with open(tmp, "w") as f:
            json.dump(meta, f, indent=1)
        os.replace(tmp, os.path.join(d, "meta.json"))
        print(f"make_scenes: {d} in {meta['render_seconds']:.1f} s", flush=True)


main()
