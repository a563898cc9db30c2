"""Builds the Blender-exported glTF fixtures in this folder (run once; the outputs are committed).

    python3 -m venv /tmp/bpy && /tmp/bpy/bin/pip install bpy==4.5.4
    /tmp/bpy/bin/python scenes/blender-showcase/make_showcase.py

Everything is made here from numbers (no downloaded asset), then written by Blender's own glTF
2.0 exporter (io_scene_gltf2 4.5.49), so the files are what a Blender user ships:

- `showcase.glb`: no camera and no light, as most downloaded assets are. A ground plane with a
  checker base-colour texture and a tangent-space normal map of ridges; a crate whose
  metallic-roughness texture makes its bands metal; a leaf quad whose base-colour alpha cuts it
  out (alpha MASK); a gold sphere; a glass sphere (KHR_materials_transmission, ior); a sign
  whose emissive texture is half black (only the lit half may become a light); five crates that
  share one mesh (instancing).
- `lit.glb`: the same objects with a camera and Blender point, spot and sun lights
  (KHR_lights_punctual).

Blender is Z-up; the exporter writes glTF's Y-up.
"""
import math
import os

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SIZE = 128


def image(name, rgba, non_color=False):
    h, w, _ = rgba.shape
    img = bpy.data.images.new(name, w, h, alpha=True)
    # Blender stores rows bottom-up.
    img.pixels = np.ascontiguousarray(rgba[::-1]).astype(np.float32).ravel()
    if non_color:
        img.colorspace_settings.name = "Non-Color"
    img.file_format = "PNG"
    img.pack()
    return img


def grid():
    v, u = np.mgrid[0:SIZE, 0:SIZE] / SIZE
    return u, v


def checker():
    u, v = grid()
    c = ((np.floor(u * 8) + np.floor(v * 8)) % 2)[..., None]
    light, dark = np.array([0.8, 0.75, 0.65, 1]), np.array([0.25, 0.3, 0.35, 1])
    return c * light + (1 - c) * dark


def ridge_normals():
    # Height h = 0.03 sin(2π·8u): tangent-space normal (−dh/du, 0, 1), normalised, in [0, 1].
    u, _ = grid()
    dh = 0.03 * 2 * math.pi * 8 * np.cos(2 * math.pi * 8 * u) * 0.5
    n = np.stack([-dh, np.zeros_like(dh), np.ones_like(dh)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.concatenate([n * 0.5 + 0.5, np.ones_like(dh)[..., None]], -1)


def bands_metal_rough():
    # glTF packs roughness in G and metalness in B: bands of rough wood and polished metal.
    u, _ = grid()
    metal = (np.floor(u * 4) % 2)[..., None]
    rough = 0.8 - 0.6 * metal
    return np.concatenate([np.ones_like(metal), rough, metal, np.ones_like(metal)], -1)


def leaf():
    u, v = grid()
    x, y = (u - 0.5) * 2, (v - 0.5) * 2
    inside = (x * x / 0.35 + y * y) < 0.9
    rgba = np.zeros((SIZE, SIZE, 4))
    rgba[..., 0], rgba[..., 1], rgba[..., 2] = 0.15, 0.55, 0.1
    rgba[..., 3] = inside
    return rgba


def half_lit_sign():
    u, v = grid()
    lit = (u < 0.5) & ((np.floor(v * 6) % 2) == 0)
    rgba = np.zeros((SIZE, SIZE, 4))
    rgba[..., 0], rgba[..., 1], rgba[..., 2] = lit * 1.0, lit * 0.6, lit * 0.2
    rgba[..., 3] = 1
    return rgba


def material(name, **k):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    p = nt.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = k.get("color", (0.8, 0.8, 0.8, 1))
    p.inputs["Metallic"].default_value = k.get("metallic", 0.0)
    p.inputs["Roughness"].default_value = k.get("roughness", 0.5)
    if "transmission" in k:
        p.inputs["Transmission Weight"].default_value = k["transmission"]
        p.inputs["IOR"].default_value = k.get("ior", 1.5)

    def tex(img):
        t = nt.nodes.new("ShaderNodeTexImage")
        t.image = img
        return t

    if "base_tex" in k:
        t = tex(k["base_tex"])
        nt.links.new(t.outputs["Color"], p.inputs["Base Color"])
        if k.get("mask"):
            # The exporter writes alphaMode MASK (cutoff 0.5) for alpha passed through Round.
            r = nt.nodes.new("ShaderNodeMath")
            r.operation = "ROUND"
            nt.links.new(t.outputs["Alpha"], r.inputs[0])
            nt.links.new(r.outputs[0], p.inputs["Alpha"])
    if "normal_tex" in k:
        t = tex(k["normal_tex"])
        nm = nt.nodes.new("ShaderNodeNormalMap")
        nt.links.new(t.outputs["Color"], nm.inputs["Color"])
        nt.links.new(nm.outputs["Normal"], p.inputs["Normal"])
    if "mr_tex" in k:
        t = tex(k["mr_tex"])
        sep = nt.nodes.new("ShaderNodeSeparateColor")
        nt.links.new(t.outputs["Color"], sep.inputs["Color"])
        nt.links.new(sep.outputs["Green"], p.inputs["Roughness"])
        nt.links.new(sep.outputs["Blue"], p.inputs["Metallic"])
    if "emissive_tex" in k:
        t = tex(k["emissive_tex"])
        nt.links.new(t.outputs["Color"], p.inputs["Emission Color"])
        p.inputs["Emission Strength"].default_value = k.get("emission_strength", 1.0)
    return m


def place(obj, location, rotation=(0, 0, 0), scale=(1, 1, 1), mat=None):
    obj.location, obj.rotation_euler, obj.scale = location, rotation, scale
    if mat is not None:
        obj.data.materials.clear()
        obj.data.materials.append(mat)
    return obj


def build(with_lights):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ground = material("ground", base_tex=image("checker", checker()),
                      normal_tex=image("ridges", ridge_normals(), non_color=True), roughness=0.6)
    crate = material("crate", color=(0.7, 0.45, 0.2, 1),
                     mr_tex=image("bands", bands_metal_rough(), non_color=True))
    leafm = material("leaf", base_tex=image("leaf", leaf()), mask=True, roughness=0.7)
    gold = material("gold", color=(1.0, 0.78, 0.34, 1), metallic=1.0, roughness=0.2)
    glass = material("glass", color=(1, 1, 1, 1), roughness=0.0, transmission=1.0, ior=1.5)
    sign = material("sign", color=(0.05, 0.05, 0.05, 1),
                    emissive_tex=image("sign", half_lit_sign()), emission_strength=4.0)

    bpy.ops.mesh.primitive_plane_add(size=6)
    place(bpy.context.object, (0, 0, 0), mat=ground).name = "ground"
    bpy.ops.mesh.primitive_cube_add(size=0.8)
    place(bpy.context.object, (-1.2, 0.4, 0.4), (0, 0, 0.4), mat=crate).name = "crate"
    bpy.ops.mesh.primitive_plane_add(size=1.2)
    place(bpy.context.object, (0.0, 1.2, 0.7), (math.pi / 2, 0, 0.3), mat=leafm).name = "leaf"
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.45, segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    place(bpy.context.object, (0.9, -0.2, 0.45), mat=gold).name = "gold"
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.35, segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    place(bpy.context.object, (0.0, -0.9, 0.35), mat=glass).name = "glass"
    bpy.ops.mesh.primitive_plane_add(size=1.0)
    place(bpy.context.object, (1.6, 1.4, 0.8), (math.pi / 2, 0, -0.5), (1.4, 0.7, 1),
          mat=sign).name = "sign"
    # Five crates sharing one mesh: the exporter writes five nodes with the same mesh index.
    bpy.ops.mesh.primitive_cube_add(size=0.25)
    small = place(bpy.context.object, (-2.2, -1.6, 0.125), mat=crate)
    small.name = "small0"
    for i in range(1, 5):
        c = small.copy()  # a linked duplicate: same mesh data
        c.location = (-2.2 + 0.4 * i, -1.6 + 0.1 * i, 0.125)
        c.name = f"small{i}"
        bpy.context.collection.objects.link(c)

    if with_lights:
        cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
        cam.data.angle_y = math.radians(40)
        bpy.context.collection.objects.link(cam)
        cam.location = (4.5, -5.0, 3.2)
        direction = -cam.location.normalized()
        cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
        for kind, loc, energy in [("POINT", (-1.5, -1.0, 2.0), 150.0), ("SPOT", (1.5, 1.5, 3.0), 400.0),
                                  ("SUN", (0, 0, 5), 2.0)]:
            light = bpy.data.objects.new(kind.lower(), bpy.data.lights.new(kind.lower(), kind))
            light.data.energy = energy
            light.location = loc
            if kind != "POINT":
                light.rotation_euler = (0.3, 0.2, 0)
            if kind == "SPOT":
                light.data.spot_size = math.radians(50)
                light.data.spot_blend = 0.3
            bpy.context.collection.objects.link(light)

    name = "lit.glb" if with_lights else "showcase.glb"
    bpy.ops.export_scene.gltf(filepath=os.path.join(HERE, name), export_format="GLB",
                              export_cameras=with_lights, export_lights=with_lights,
                              export_yup=True, export_apply=False)


build(with_lights=False)
build(with_lights=True)
