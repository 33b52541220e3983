"""Tests of convert.py without Blender: a hand-made raw render goes through `convert_scene` and every
element is checked against what it must be. Run: python scripts/blender-scenes/test_convert.py
(numpy, Pillow, OpenEXR)."""

import json
import math
import os
import struct
import sys
import tempfile
import unittest

import numpy as np
import OpenEXR
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import convert  # noqa: E402


def write_pat(path, px, name=b"test"):
    h, w, bpp = px.shape
    header = struct.pack(">5I", 24 + len(name) + 1, 1, w, h, bpp) + b"GPAT" + name + b"\0"
    with open(path, "wb") as f:
        f.write(header + px.astype(np.uint8).tobytes())


def write_raw_exr(path, chans):
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in chans.items()}) as f:
        f.write(path)


class Pat(unittest.TestCase):
    def test_rgb_and_grey_patterns(self):
        rng = np.random.default_rng(1)
        with tempfile.TemporaryDirectory() as d:
            rgb = rng.integers(0, 256, (5, 7, 3))
            write_pat(os.path.join(d, "a.pat"), rgb)
            got = np.asarray(convert.read_pat(os.path.join(d, "a.pat")))
            np.testing.assert_array_equal(got, rgb)
            grey = rng.integers(0, 256, (4, 6, 1))
            write_pat(os.path.join(d, "g.pat"), grey)
            got = np.asarray(convert.read_pat(os.path.join(d, "g.pat")))
            np.testing.assert_array_equal(got, np.repeat(grey, 3, axis=2))

    def test_truncated_and_foreign_files_are_refused(self):
        with tempfile.TemporaryDirectory() as d:
            p = os.path.join(d, "t.pat")
            write_pat(p, np.zeros((4, 4, 3)))
            with open(p, "rb") as fh:
                data = fh.read()
            with open(p, "wb") as fh:
                fh.write(data[:-5])
            with self.assertRaisesRegex(ValueError, "truncated"):
                convert.read_pat(p)
            with open(p, "wb") as fh:
                fh.write(b"\x00" * 40)
            with self.assertRaisesRegex(ValueError, "not a GIMP pattern"):
                convert.read_pat(p)


class Scene(unittest.TestCase):
    def test_elements_of_a_hand_made_render(self):
        h, w = 6, 8
        rng = np.random.default_rng(2)
        with tempfile.TemporaryDirectory() as d:
            raw, out = os.path.join(d, "raw"), os.path.join(d, "out")
            os.makedirs(raw)
            tile = rng.integers(0, 256, (4, 5, 3)).astype(np.uint8)
            tile_path = os.path.join(d, "src__tile.png")
            Image.fromarray(tile).save(tile_path)
            # Camera pitched down by 30°: columns are its x, y, z axes in the (z-up) world.
            p = math.radians(-30)
            # Blender's camera rotation_euler = (90° + pitch, 0, 0): a rotation about x.
            a = math.pi / 2 + p
            rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
            rot = [list(rx[:, 0]), list(rx[:, 1]), list(rx[:, 2])]
            ids = np.zeros((h, w))
            ids[3:, :] = 1  # floor (textured)
            ids[:3, 4:] = 2  # a single-colour wall; ids[:3, :4] = 0 is the sky
            normal_w = np.zeros((3, h, w))
            normal_w[2, 3:, :] = 1.0  # floor faces up
            normal_w[1, :3, 4:] = -1.0  # the wall faces -y (towards the camera, which looks along +y)
            u = rng.uniform(-3, 3, (h, w))
            v = rng.uniform(-3, 3, (h, w))
            diff = rng.uniform(0, 1, (3, h, w))
            combined = rng.uniform(0.01, 2.0, (3, h, w))
            chans = {f"ViewLayer.Combined.{c}": combined[i] for i, c in enumerate("RGB")}
            chans.update({f"ViewLayer.DiffCol.{c}": diff[i] for i, c in enumerate("RGB")})
            chans.update({f"ViewLayer.Normal.{c}": normal_w[i] for i, c in enumerate("XYZ")})
            chans.update({"ViewLayer.UV.U": u, "ViewLayer.UV.V": v, "ViewLayer.UV.A": np.ones((h, w)),
                          "ViewLayer.IndexMA.X": ids, "ViewLayer.Depth.Z": np.full((h, w), 2.5)})
            write_raw_exr(os.path.join(raw, "render.exr"), chans)
            env = rng.uniform(0, 5, (3, h // 2, w // 2))
            write_raw_exr(os.path.join(raw, "env.exr"),
                          {f"ViewLayer.Combined.{c}": env[i] for i, c in enumerate("RGB")})
            meta = {
                "index": 0, "seed": 5, "width": w, "height": h, "samples": 16, "blender": "test",
                "room_m": [3, 3, 3], "window": None, "lights": [], "sky": {},
                "camera": {"position": [1, 1, 1.5], "fov_y_deg": 60.0, "yaw_deg": 0.0,
                           "pitch_deg": -30.0, "roll_deg": 0.0, "rotation": rot},
                "materials": [
                    {"id": 1, "name": "floor", "textured": True, "texture": tile_path,
                     "roughness": 0.5, "specular": 0.5, "tiling": {"tile_m": [1, 1]}},
                    {"id": 2, "name": "walls", "textured": False, "diffuse_colour": [0.2, 0.4, 0.6],
                     "roughness": 0.9, "specular": 0.25},
                ],
            }
            with open(os.path.join(raw, "meta.json"), "w") as fh:
                json.dump(meta, fh)
            convert.convert_scene(raw, out, np.random.default_rng(0))

            def exr(name):
                with OpenEXR.File(os.path.join(out, name), separate_channels=True) as f:
                    ch = f.channels()
                    keys = ["R", "G", "B"] if "R" in ch else ["Y"]
                    return np.stack([np.asarray(ch[k].pixels, np.float64) for k in keys])

            got_ids = np.asarray(Image.open(os.path.join(out, "material_id.png")))
            np.testing.assert_array_equal(got_ids, ids)
            # Normals in the camera frame: the floor's up is the camera's frame rotated by the pitch.
            n = exr("normals.exr")
            want_floor = rx.T @ np.array([0, 0, 1.0])
            np.testing.assert_allclose(n[:, 4, 2], want_floor, atol=1e-6)
            self.assertAlmostEqual(want_floor[1], math.cos(p), places=6)  # mostly up in the picture
            vv = exr("view_vector.exr")
            np.testing.assert_allclose(np.linalg.norm(vv, axis=0), 1.0, atol=1e-6)
            self.assertTrue((vv[2] > 0).all())  # towards the camera: +z
            np.testing.assert_allclose(n[:, 0, 0], vv[:, 0, 0], atol=1e-6)  # sky: the view vector
            self.assertTrue(((n * vv).sum(0) >= -1e-6).all())  # nothing faces away
            # UV: wrapped, v flipped (Blender's v = 0 is the image's bottom row), t = 1 on the floor only.
            uv = exr("uv.exr")
            sel = ids == 1
            np.testing.assert_allclose(uv[0][sel], (u - np.floor(u))[sel], atol=1e-6)
            np.testing.assert_allclose(uv[1][sel], ((1 - v) - np.floor(1 - v))[sel], atol=1e-6)
            np.testing.assert_array_equal(uv[2], sel.astype(float))
            self.assertTrue((uv[:2][:, ~sel] == 0).all())
            # The true texture is the tile, linear.
            tex = exr("materials/1/texture.exr")
            np.testing.assert_allclose(tex, convert.srgb_decode(tile.transpose(2, 0, 1) / 255.0), atol=1e-6)
            # Phong parameters from the Principled ones.
            spec, gloss = exr("specular_albedo.exr"), exr("glossiness.exr")
            np.testing.assert_allclose(spec[:, 4, 0], 0.04, atol=1e-7)
            np.testing.assert_allclose(spec[:, 0, 6], 0.02, atol=1e-7)
            n_floor = (2 / 0.25 ** 2 - 2) / 4
            self.assertAlmostEqual(gloss[0, 4, 0], math.log2(n_floor) / 13, places=6)
            self.assertEqual(gloss[0, 0, 0], 0.0)
            # Segmentation: (mean albedo + specular)/2 per material, 0 for the sky.
            seg = exr("segmentation.exr")
            np.testing.assert_allclose(seg[:, 0, 6], (np.array([0.2, 0.4, 0.6]) + 0.02) / 2, atol=1e-6)
            np.testing.assert_allclose(seg[:, 5, 5], (tex.reshape(3, -1).mean(1) + 0.04) / 2, atol=1e-6)
            self.assertTrue((seg[:, 0, 0] == 0).all())
            # Exposure: the image's log-average luminance is the drawn key.
            with open(os.path.join(out, "scene.json")) as fh:
                scene = json.load(fh)
            lin = exr("image.exr")
            lum = 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]
            self.assertAlmostEqual(math.exp(np.log(np.maximum(lum, 1e-4)).mean()), scene["key"], places=4)
            np.testing.assert_allclose(exr("envmap.exr"), env * scene["exposure"], rtol=1e-6)
            png = np.asarray(Image.open(os.path.join(out, "image.png")))
            self.assertEqual(png.shape, (h, w, 3))
            self.assertEqual([m["id"] for m in scene["materials"]], [1, 2])
            self.assertEqual(scene["camera"]["fov_y_deg"], 60.0)
            self.assertEqual(scene["materials"][0]["family"], "blender:src")
            self.assertTrue((exr("diffuse_albedo.exr")[:, :3, :4] == 0).all())

    def test_half_exrs_keep_values_to_half_precision(self):
        rng = np.random.default_rng(5)
        planes = rng.uniform(-2.0, 2.0, (3, 4, 5)).astype(np.float32)
        planes[0, 0, 0] = 1e6  # beyond half's range: clipped to its largest finite value
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "x.exr")
            old = convert.EXR_DTYPE
            convert.EXR_DTYPE = np.float16
            try:
                convert.write_exr(path, planes)
            finally:
                convert.EXR_DTYPE = old
            with OpenEXR.File(path, separate_channels=True) as f:
                ch = f.channels()
                self.assertEqual(ch["R"].pixels.dtype, np.float16)
                got = np.stack([np.asarray(ch[k].pixels, np.float32) for k in "RGB"])
            self.assertEqual(got[0, 0, 0], 65504.0)
            want = planes.copy()
            want[0, 0, 0] = 65504.0
            np.testing.assert_allclose(got, want, rtol=2 ** -11, atol=0)
            self.assertFalse(os.path.exists(path + ".tmp.exr"))


if __name__ == "__main__":
    unittest.main()
