#!/usr/bin/env python3
"""The LuxCore export of luxcore.py, without LuxCore or Flowlight (standard library only):

    python3 crates/flowlight-bench/peers/test_luxcore.py

It checks the camera from a matrix against the same camera from a translation and rotation,
the glass caustic's and the Cornell box's materials, the one-line refusals of what does not
export, and the Flowlight configs the plugin-only renderers get."""
import contextlib
import io
import json
import os
import sys
import tempfile
import types
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import luxcore  # noqa: E402

SCENES = os.path.join(luxcore.ROOT, "scenes")


def refusal(fn, *args):
    """The one-line error `fn(*args)` exits with, or None when it returns."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            fn(*args)
        except SystemExit:
            return err.getvalue()
    return None


class Camera(unittest.TestCase):
    def test_rotation_and_matrix_give_the_same_camera(self):
        # 180 degrees about y, as the Cornell box's camera, written both ways.
        trs = {"nodes": [{"camera": 0, "translation": [1, 2, 3], "rotation": [0, 1, 0, 0]}],
               "cameras": [{"type": "perspective", "perspective": {"yfov": 0.5}}]}
        matrix = {"nodes": [{"camera": 0, "matrix": [-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0,
                                                     1, 2, 3, 1]}],
                  "cameras": trs["cameras"]}
        a, b = luxcore.camera(trs, "trs"), luxcore.camera(matrix, "matrix")
        for u, v in zip(a[:3], b[:3]):
            self.assertEqual([round(x, 12) for x in u], [round(x, 12) for x in v])
        self.assertEqual(b[1], [0, 0, 1])

    def test_cornell_box_camera_looks_along_z(self):
        g = json.load(open(os.path.join(SCENES, "cornell-box", "cornell-box.gltf")))
        origin, forward, up, fov = luxcore.camera(g, "cornell-box.gltf")
        self.assertEqual(origin, [0.278, 0.273, -0.8])
        self.assertEqual([round(x, 12) for x in forward], [0, 0, 1])
        self.assertEqual([round(x, 12) for x in up], [0, 1, 0])
        self.assertAlmostEqual(fov, 39.3077, places=4)

    def test_child_camera_is_refused(self):
        g = {"nodes": [{"children": [1]}, {"camera": 0, "name": "eye"}],
             "cameras": [{"type": "perspective", "perspective": {"yfov": 0.5}}]}
        self.assertIn("has a parent", refusal(luxcore.camera, g, "x.gltf"))


class Materials(unittest.TestCase):
    def test_glass_caustic(self):
        g = json.load(open(os.path.join(SCENES, "glass-caustic", "glass-caustic.gltf")))
        by_name = {m["name"]: luxcore.luxcore_material("g", m) for m in g["materials"]}
        self.assertEqual(by_name["floor"], ["type = matte", "kd = 0.7 0.7 0.7"])
        self.assertEqual(by_name["glass"], ["type = glass", "kr = 1 1 1", "kt = 1 1 1",
                                            "exteriorior = 1", "interiorior = 1.5"])
        self.assertIn("emission = 120 114 102", by_name["lamp"])
        self.assertIn("emission.power = 0", by_name["lamp"])

    def test_cornell_box_light_keeps_its_albedo(self):
        g = json.load(open(os.path.join(SCENES, "cornell-box", "cornell-box.gltf")))
        light = next(m for m in g["materials"] if m["name"] == "light")
        lines = luxcore.luxcore_material("c", light)
        self.assertIn("kd = 0.936461 0.740433 0.705267", lines)
        self.assertIn("emission = 18.387 10.9873 2.75357", lines)

    def test_what_does_not_export_is_refused_by_name(self):
        plain = {"name": "m", "pbrMetallicRoughness": {"metallicFactor": 0.0}}
        cases = {
            "has textures": {**plain, "pbrMetallicRoughness": {
                "metallicFactor": 0.0, "baseColorTexture": {"index": 0}}},
            "is metallic": {"name": "m"},
            "alphaMode BLEND": {**plain, "alphaMode": "BLEND"},
            "KHR_materials_clearcoat": {**plain, "extensions": {"KHR_materials_clearcoat": {}}},
            "only smooth, white": {"name": "m", "pbrMetallicRoughness": {
                "metallicFactor": 0.0, "roughnessFactor": 0.2},
                "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}}},
            "volume attenuation": {"name": "m", "pbrMetallicRoughness": {
                "metallicFactor": 0.0, "roughnessFactor": 0.0},
                "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                               "KHR_materials_volume": {"attenuationDistance": 1.0}}},
        }
        for why, mat in cases.items():
            msg = refusal(luxcore.luxcore_material, "x.gltf", mat)
            self.assertIsNotNone(msg, why)
            self.assertIn("material 'm'", msg)
            self.assertIn(why, msg)
            self.assertEqual(msg.count("\n"), 1, msg)
        self.assertIsNone(refusal(luxcore.luxcore_material, "x.gltf", plain))


class Configs(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.a = types.SimpleNamespace(width=64, height=64, without=[])

    def tearDown(self):
        self.dir.cleanup()

    def test_plugin_only_config_keeps_the_scene_and_its_depth_and_drops_the_rest(self):
        src = os.path.join(SCENES, "glass-caustic", "erpt.toml")
        out = luxcore.flowlight_config(self.a, src, "s.gltf", os.path.join(self.dir.name, "v.toml"),
                                       "vcm")
        text = open(out).read()
        self.assertIn('[integrator]\nplugin = "vcm"\npath_depth = 10\n', text)
        self.assertEqual(text.count("plugin ="), 1)
        self.assertNotIn("termination =", text)
        self.assertNotIn("[output]", text)
        self.assertIn("width = 64", text)
        self.assertIn('scene = "s.gltf"', text)

    def test_without_config_keeps_erpt_mutations(self):
        src = os.path.join(SCENES, "glass-caustic", "erpt.toml")
        out = luxcore.flowlight_config(self.a, src, "s.gltf", os.path.join(self.dir.name, "e.toml"))
        text = open(out).read()
        self.assertEqual(text.count("[[integrator.mutations]]"), 2)
        self.assertIn('plugin = "erpt"', text)

    def test_without_leaves_the_node_out_of_both_scenes(self):
        self.a.without = ["glass"]
        scene_dir = os.path.join(SCENES, "glass-caustic")
        lines = luxcore.luxcore_scene(self.a, os.path.join(scene_dir, "glass-caustic.gltf"),
                                      self.dir.name)
        self.assertFalse(any(".glass." in line for line in lines))
        self.assertTrue(any(line.startswith("scene.objects.lamp.") for line in lines))
        g = json.load(open(luxcore.lambert_gltf(self.a, scene_dir, "glass-caustic", self.dir.name)))
        glass = next(n for n in g["nodes"] if n.get("name") == "glass")
        self.assertNotIn("mesh", glass)
        self.a.without = ["nothing"]
        self.assertIn("no mesh node named nothing", refusal(
            luxcore.luxcore_scene, self.a, os.path.join(scene_dir, "glass-caustic.gltf"),
            self.dir.name))


if __name__ == "__main__":
    unittest.main(warnings="ignore")  # the scripts open files the short way
