#!/usr/bin/env python3
"""Generates the benchmark scenes of scenes/suite.toml (glTF 2.0 with an embedded buffer, and a
render config each). Standard library only; deterministic output.

    python3 scenes/tools/make_scenes.py          # rewrites scenes/<name>/<name>.gltf and .toml

Scenes (y up, metres):
  indirect-room  a room lit only from a lamp hidden in a back room behind a partition with a
                 doorway: nearly all light seen from the camera arrives after 2+ bounces.
  glass-caustic  a smooth glass sphere (KHR_materials_transmission, ior 1.5) on a diffuse floor
                 under a small lamp: the caustic under the sphere is made of LSDE paths.
  mirror-chain   a narrow corridor between two parallel perfect mirrors (metallic 1, roughness
                 0): camera rays at the image edge bounce more than 10 times before reaching
                 the diffuse floor or end wall.
  narrow-gap     a slab 2 cm above the floor in a corner, lit from above: the floor under it is
                 lit only through the 2 cm gaps (the thesis' corner and cavity traps).
"""

import base64
import json
import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = os.path.dirname(HERE)


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def dot(a, b):
    return sum(a[i] * b[i] for i in range(3))


def norm(a):
    n = math.sqrt(dot(a, a))
    return [x / n for x in a]


class Builder:
    def __init__(self, generator):
        self.generator = generator
        self.materials = []
        self.mat_index = {}
        self.meshes = {}  # material name -> (positions, normals or None, indices)
        self.order = []
        self.extensions = set()

    def material(self, name, base=(0.8, 0.8, 0.8), metallic=0.0, roughness=1.0,
                 emission=None, transmission=None, ior=None, thickness=None):
        m = {
            "name": name,
            "pbrMetallicRoughness": {
                "baseColorFactor": [base[0], base[1], base[2], 1.0],
                "metallicFactor": metallic,
                "roughnessFactor": roughness,
            },
            "doubleSided": True,
        }
        ext = {}
        if emission is not None:
            rgb, strength = emission
            m["emissiveFactor"] = list(rgb)
            ext["KHR_materials_emissive_strength"] = {"emissiveStrength": strength}
        if transmission is not None:
            ext["KHR_materials_transmission"] = {"transmissionFactor": transmission}
        if ior is not None:
            ext["KHR_materials_ior"] = {"ior": ior}
        if thickness is not None:
            # A closed volume: transmission refracts (without it glTF is thin-walled).
            ext["KHR_materials_volume"] = {"thicknessFactor": thickness}
        if ext:
            m["extensions"] = ext
            self.extensions.update(ext.keys())
        self.mat_index[name] = len(self.materials)
        self.materials.append(m)

    def _mesh(self, mat, smooth):
        if mat not in self.meshes:
            self.meshes[mat] = ([], [] if smooth else None, [])
            self.order.append(mat)
        return self.meshes[mat]

    def quad(self, mat, p0, p1, p2, p3, facing=None):
        """A planar quad p0 p1 p2 p3 (in order around it). `facing`: the direction its front
        (counter-clockwise) face must point to; the winding is flipped to match."""
        pos, _, idx = self._mesh(mat, False)
        n = cross(sub(p1, p0), sub(p2, p0))
        pts = [p0, p1, p2, p3]
        if facing is not None and dot(n, facing) < 0:
            pts = [p0, p3, p2, p1]
        base = len(pos)
        pos.extend(pts)
        idx.extend([base, base + 1, base + 2, base, base + 2, base + 3])

    def box(self, mat, lo, hi):
        """An axis-aligned closed box, faces pointing outwards."""
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        c = [(lo[i] + hi[i]) / 2 for i in range(3)]
        faces = [
            ([x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]),
            ([x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]),
            ([x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]),
            ([x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]),
            ([x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]),
            ([x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]),
        ]
        for f in faces:
            fc = [sum(p[i] for p in f) / 4 for i in range(3)]
            self.quad(mat, *f, facing=sub(fc, c))

    def sphere(self, mat, centre, radius, subdivisions):
        """An icosphere with smooth vertex normals."""
        t = (1 + math.sqrt(5)) / 2
        verts = [norm(v) for v in [
            [-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
            [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]]
        faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                 [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                 [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                 [8, 6, 7], [9, 8, 1]]
        for _ in range(subdivisions):
            cache = {}

            def mid(a, b):
                key = (min(a, b), max(a, b))
                if key not in cache:
                    verts.append(norm([(verts[a][i] + verts[b][i]) / 2 for i in range(3)]))
                    cache[key] = len(verts) - 1
                return cache[key]

            new = []
            for a, b, c in faces:
                ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
                new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            faces = new
        pos, nrm, idx = self._mesh(mat, True)
        base = len(pos)
        for v in verts:
            pos.append([centre[i] + radius * v[i] for i in range(3)])
            nrm.append(v)
        for f in faces:
            idx.extend(base + i for i in f)

    def gltf(self, camera_pos, look_at, yfov_deg, aspect=1.0):
        blob = bytearray()
        views, accessors, meshes, nodes = [], [], [], []

        def add_view(data, target):
            while len(blob) % 4:
                blob.append(0)
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data),
                          "target": target})
            blob.extend(data)
            return len(views) - 1

        triangles = 0
        for mat in self.order:
            pos, nrm, idx = self.meshes[mat]
            flat = [c for p in pos for c in p]
            pv = add_view(struct.pack("<%df" % len(flat), *flat), 34962)
            lo = [min(p[i] for p in pos) for i in range(3)]
            hi = [max(p[i] for p in pos) for i in range(3)]
            accessors.append({"bufferView": pv, "componentType": 5126, "count": len(pos),
                              "type": "VEC3", "min": lo, "max": hi})
            attrs = {"POSITION": len(accessors) - 1}
            if nrm is not None:
                flat = [c for p in nrm for c in p]
                nv = add_view(struct.pack("<%df" % len(flat), *flat), 34962)
                accessors.append({"bufferView": nv, "componentType": 5126, "count": len(nrm),
                                  "type": "VEC3"})
                attrs["NORMAL"] = len(accessors) - 1
            assert len(pos) < 65536
            iv = add_view(struct.pack("<%dH" % len(idx), *idx), 34963)
            accessors.append({"bufferView": iv, "componentType": 5123, "count": len(idx),
                              "type": "SCALAR"})
            meshes.append({"name": mat, "primitives": [{
                "attributes": attrs, "indices": len(accessors) - 1,
                "material": self.mat_index[mat]}]})
            nodes.append({"name": mat, "mesh": len(meshes) - 1})
            triangles += len(idx) // 3

        # Camera: looks along its local -Z with +Y up.
        f = norm(sub(look_at, camera_pos))
        r = norm(cross(f, [0, 1, 0]))
        u = cross(r, f)
        m = [r[0], r[1], r[2], 0, u[0], u[1], u[2], 0, -f[0], -f[1], -f[2], 0,
             camera_pos[0], camera_pos[1], camera_pos[2], 1]
        nodes.append({"name": "camera", "camera": 0, "matrix": [round(x, 7) for x in m]})
        doc = {
            "asset": {"version": "2.0", "generator": self.generator},
            "scene": 0,
            "scenes": [{"nodes": list(range(len(nodes)))}],
            "nodes": nodes,
            "cameras": [{"type": "perspective", "perspective": {
                "yfov": math.radians(yfov_deg), "znear": 0.01, "aspectRatio": aspect}}],
            "meshes": meshes,
            "materials": self.materials,
            "accessors": accessors,
            "bufferViews": views,
            "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                         + base64.b64encode(bytes(blob)).decode()}],
        }
        if self.extensions:
            doc["extensionsUsed"] = sorted(self.extensions)
        return doc, triangles


def write(name, builder, camera, comment, path_depth=8, size=256):
    folder = os.path.join(SCENES, name)
    os.makedirs(folder, exist_ok=True)
    doc, tris = builder.gltf(*camera)
    with open(os.path.join(folder, name + ".gltf"), "w") as f:
        json.dump(doc, f, separators=(",", ":"))
        f.write("\n")
    with open(os.path.join(folder, name + ".toml"), "w") as f:
        f.write("".join("# " + line + "\n" for line in comment.strip().splitlines()))
        f.write("# Generated by scenes/tools/make_scenes.py (%d triangles).\n" % tris)
        f.write('scene = "%s.gltf"\n\n[render]\nwidth = %d\nheight = %d\nspp = 64\nseed = 1\n\n'
                % (name, size, size))
        f.write('[integrator]\nplugin = "mcpt"\nvariant = "entangled"\ntermination = "bxdf"\n'
                'path_depth = %d\n\n[output]\nexr = "%s.exr"\npng = "%s.png"\n'
                % (path_depth, name, name))
    print("%-14s %5d triangles" % (name, tris))


def indirect_room():
    b = Builder("flowlight scenes/tools/make_scenes.py: indirect-room")
    b.material("white", (0.75, 0.75, 0.75))
    b.material("floor", (0.55, 0.5, 0.45))
    b.material("red", (0.65, 0.15, 0.1))
    b.material("lamp", (0, 0, 0), emission=((1.0, 0.9, 0.75), 150.0))
    W, H, D, P = 4.0, 2.5, 5.0, 3.5  # width, height, depth, partition z
    b.quad("floor", [0, 0, 0], [W, 0, 0], [W, 0, D], [0, 0, D], facing=[0, 1, 0])
    b.quad("white", [0, H, 0], [W, H, 0], [W, H, D], [0, H, D], facing=[0, -1, 0])
    b.quad("red", [0, 0, 0], [0, H, 0], [0, H, D], [0, 0, D], facing=[1, 0, 0])
    b.quad("white", [W, 0, 0], [W, H, 0], [W, H, D], [W, 0, D], facing=[-1, 0, 0])
    b.quad("white", [0, 0, 0], [W, 0, 0], [W, H, 0], [0, H, 0], facing=[0, 0, 1])
    b.quad("white", [0, 0, D], [W, 0, D], [W, H, D], [0, H, D], facing=[0, 0, -1])
    # Partition with a doorway x in [2.6, 3.4], y in [0, 2].
    b.quad("white", [0, 0, P], [2.6, 0, P], [2.6, H, P], [0, H, P], facing=[0, 0, -1])
    b.quad("white", [3.4, 0, P], [W, 0, P], [W, H, P], [3.4, H, P], facing=[0, 0, -1])
    b.quad("white", [2.6, 2.0, P], [3.4, 2.0, P], [3.4, H, P], [2.6, H, P], facing=[0, 0, -1])
    # The lamp hangs in the back room, far from the doorway, and shines up at the ceiling.
    b.quad("lamp", [0.5, 2.0, 4.0], [1.3, 2.0, 4.0], [1.3, 2.0, 4.6], [0.5, 2.0, 4.6],
           facing=[0, 1, 0])
    b.box("white", [0.9, 0.0, 1.8], [1.7, 0.8, 2.6])
    write("indirect-room", b, ([2.0, 1.4, 0.25], [2.3, 0.9, 3.5], 62.0), """
Indirect interior: a room lit only by a lamp in a back room behind a partition, shining at the
back room's ceiling. Seen from the camera, almost all light has bounced twice or more.""",
          path_depth=10)


def glass_caustic():
    b = Builder("flowlight scenes/tools/make_scenes.py: glass-caustic")
    b.material("floor", (0.7, 0.7, 0.7))
    b.material("wall", (0.6, 0.6, 0.65))
    b.material("glass", (1, 1, 1), roughness=0.0, transmission=1.0, ior=1.5, thickness=1.0)
    b.material("lamp", (0, 0, 0), emission=((1.0, 0.95, 0.85), 120.0))
    b.quad("floor", [-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2], facing=[0, 1, 0])
    b.quad("wall", [-2, 0, 2], [2, 0, 2], [2, 2.5, 2], [-2, 2.5, 2], facing=[0, 0, -1])
    b.sphere("glass", [0.0, 0.52, 0.0], 0.5, 3)
    b.quad("lamp", [0.15, 2.4, -0.55], [0.5, 2.4, -0.55], [0.5, 2.4, -0.2], [0.15, 2.4, -0.2],
           facing=[0, -1, 0])
    write("glass-caustic", b, ([0.0, 1.5, -3.0], [0.0, 0.35, 0.2], 40.0), """
Caustic: a smooth glass sphere (transmission 1, ior 1.5) on a diffuse floor under a small lamp.
The bright spot under and behind the sphere is light through the glass onto the floor (LS+DE
paths): path tracing finds it only by BSDF sampling hits on the small lamp.""", path_depth=10)


def mirror_chain():
    b = Builder("flowlight scenes/tools/make_scenes.py: mirror-chain")
    b.material("floor", (0.6, 0.6, 0.6))
    b.material("end", (0.7, 0.5, 0.3))
    b.material("mirror", (0.95, 0.95, 0.95), metallic=1.0, roughness=0.0)
    b.material("block", (0.2, 0.4, 0.7))
    b.material("lamp", (0, 0, 0), emission=((1.0, 1.0, 1.0), 30.0))
    W, L, H = 0.4, 8.0, 1.5
    b.quad("floor", [0, 0, -1], [W, 0, -1], [W, 0, L], [0, 0, L], facing=[0, 1, 0])
    b.quad("mirror", [0, 0, -1], [0, H, -1], [0, H, L], [0, 0, L], facing=[1, 0, 0])
    b.quad("mirror", [W, 0, -1], [W, H, -1], [W, H, L], [W, 0, L], facing=[-1, 0, 0])
    b.quad("end", [0, 0, L], [W, 0, L], [W, H, L], [0, H, L], facing=[0, 0, -1])
    b.box("block", [0.12, 0.0, 3.5], [0.28, 0.25, 3.66])
    b.quad("lamp", [0.05, H, 5.5], [W - 0.05, H, 5.5], [W - 0.05, H, 6.5], [0.05, H, 6.5],
           facing=[0, -1, 0])
    write("mirror-chain", b, ([0.2, 0.9, 0.0], [0.55, 0.45, 3.0], 45.0), """
Mirror chain: a corridor 0.4 wide between two parallel perfect mirrors (metallic 1, roughness 0),
open at the top, lit by a lamp near its end. Rays at the image edges bounce between the mirrors
more than 10 times (tan 40 deg x 8 / 0.4 = 17) before they reach the floor or the end wall, so
virtual depth matters: path_depth counts lighting bounces, max_ray_depth every bounce.""",
          path_depth=8)


def narrow_gap():
    b = Builder("flowlight scenes/tools/make_scenes.py: narrow-gap")
    b.material("floor", (0.7, 0.7, 0.7))
    b.material("wall", (0.7, 0.7, 0.7))
    b.material("slab", (0.6, 0.3, 0.2))
    b.material("lamp", (0, 0, 0), emission=((1.0, 0.95, 0.9), 20.0))
    b.quad("floor", [-1.5, 0, -1.5], [1.5, 0, -1.5], [1.5, 0, 1.5], [-1.5, 0, 1.5],
           facing=[0, 1, 0])
    b.quad("wall", [-1.5, 0, -1.5], [-1.5, 2, -1.5], [-1.5, 2, 1.5], [-1.5, 0, 1.5],
           facing=[1, 0, 0])
    b.quad("wall", [-1.5, 0, 1.5], [1.5, 0, 1.5], [1.5, 2, 1.5], [-1.5, 2, 1.5],
           facing=[0, 0, -1])
    # A slab 2 cm above the floor and 2 cm from both walls: the corner under it is a cavity.
    b.box("slab", [-1.48, 0.02, 0.28], [-0.28, 0.12, 1.48])
    b.quad("lamp", [0.2, 2.0, -0.6], [0.7, 2.0, -0.6], [0.7, 2.0, -0.1], [0.2, 2.0, -0.1],
           facing=[0, -1, 0])
    write("narrow-gap", b, ([0.6, 0.45, -1.4], [-0.7, 0.03, 0.7], 45.0), """
Narrow gap and corner: a slab floating 2 cm above the floor and 2 cm from the two walls of a
corner, lit from above. The floor under the slab gets light only through the 2 cm gaps, and the
wall-floor corners are the thesis' corner traps.""")


if __name__ == "__main__":
    indirect_room()
    glass_caustic()
    mirror_chain()
    narrow_gap()
