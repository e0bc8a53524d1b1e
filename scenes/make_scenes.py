#!/usr/bin/env python3
"""Generate the glTF 2.0 scenes bundled with hemirad.

    python3 scenes/make_scenes.py

writes, next to this script:

    cornell_box.gltf   the Cornell box from the Cornell Program of Computer Graphics
                       "Cornell Box Data" (https://www.graphics.cornell.edu/online/box/data.html)
    closed_room.gltf   a closed 4 m x 2.5 m x 5 m room with a ceiling panel light and a cube
    empty_room.gltf    the same room, empty and grey, its light flush with the ceiling
    double_sided_cylinder.gltf  a 168-triangle double-sided emissive cylinder under rotated and
                       scaled nodes, in a closed grey room
    lamp_facing_sky.gltf  a two-sided lamp whose brighter side faces the open sky, 1 m above a floor
    curved_objects.gltf   a double-sided vertex-coloured torus and a sphere under mirroring node
                       chains, in the closed room
    lit_room.gltf      the closed room lit by a point and a spot light (KHR_lights_punctual),
                       with a repeated floor texture, an alpha-masked card and an emissive sign
    leaf_canopy.gltf   300 double-sided leaf cards in a crown, 160 glowing ones in a dense crown by
                       a wall and 48 emitting lantern cards, none sharing an edge, in the closed room
    night_street.gltf  two houses on a street at night, lit only by two crowns of emitting leaf
                       cards and a string of lantern cards, none sharing an edge, open to the sky
    atrium.gltf        a 6 m x 4 m x 6 m atrium lit only by the sun (a KHR_lights_punctual
                       directional light) through a 2 m x 2 m opening in its roof, with a block
                       in the sunlit patch; bake it with --sky for the sky through the opening

Python 3 standard library only; the output is byte-for-byte deterministic.

Conventions (see DESIGN.md): glTF 2.0, Y-up, a triangle's front is its counter-clockwise
side, emission = emissiveFactor x KHR_materials_emissive_strength, reflectance =
baseColorFactor.rgb (x COLOR_0 where a mesh has vertex colours). The rooms' surfaces are
one-sided (doubleSided false); the cylinder and the torus are double-sided, and the lamp facing
the sky is two one-sided quads back to back, one per emission.

Every flat surface is a quad written as two indexed triangles (0,1,2) and (0,2,3) sharing the
diagonal 0-2; the curved objects are tessellated. The winding is computed, not trusted: each quad is flipped if needed so its
front faces into the room/box (or out of a block), and after writing, the file is read back
and every triangle is checked again.
"""

import base64
import json
import math
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))

EMISSIVE_EXT = "KHR_materials_emissive_strength"

# --------------------------------------------------------------------------------------
# small vector helpers
# --------------------------------------------------------------------------------------


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def norm(a):
    return math.sqrt(dot(a, a))


def unit(a):
    n = norm(a)
    assert n > 0.0, "degenerate vector"
    return (a[0] / n, a[1] / n, a[2] / n)


def mean(points):
    n = float(len(points))
    return (sum(p[0] for p in points) / n, sum(p[1] for p in points) / n, sum(p[2] for p in points) / n)


def tri_normal(a, b, c):
    """Unit normal of the counter-clockwise (front) side of triangle a, b, c."""
    return unit(cross(sub(b, a), sub(c, a)))


def f32(x):
    """Round a Python float to the nearest float32 (what ends up in the buffer)."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


QUAD_TRIS = ((0, 1, 2), (0, 2, 3))

# --------------------------------------------------------------------------------------
# orientation rules: a rule takes a triangle's (normal, centroid) and says whether its
# front faces the right way.
# --------------------------------------------------------------------------------------


def faces_towards(point):
    """Front faces towards `point` (e.g. the inside of a room)."""
    return ("towards", tuple(point))


def faces_away_from(point):
    """Front faces away from `point` (e.g. the outside of a block)."""
    return ("away", tuple(point))


def faces_direction(d):
    """Front faces (nearly exactly) along direction d."""
    return ("direction", tuple(unit(d)))


def faces_half(d):
    """Front faces into the half-space along direction d (a leaf facing up, tilted up to 90 degrees)."""
    return ("half", tuple(unit(d)))


def closed_outward():
    """The node's triangles form a closed surface facing out (checked as a whole: every edge
    matched by its reverse, and a positive enclosed volume), for shapes like a torus."""
    return ("closed_outward", None)


def check_rule(rule, n, centroid):
    kind, p = rule
    if kind == "closed_outward":
        return True
    if kind == "towards":
        return dot(n, sub(p, centroid)) > 0.0
    if kind == "away":
        return dot(n, sub(centroid, p)) > 0.0
    if kind == "direction":
        return dot(n, p) > 0.999
    if kind == "half":
        return dot(n, p) > 0.0
    raise ValueError(kind)


def orient_quad(quad, rule):
    """Return the quad's 4 corners, reversed if needed, so both triangles obey `rule`."""
    quad = [tuple(float(c) for c in v) for v in quad]
    assert len(quad) == 4

    def ok(q):
        return all(check_rule(rule, tri_normal(*(q[i] for i in t)), mean([q[i] for i in t])) for t in QUAD_TRIS)

    if ok(quad):
        return quad
    flipped = [quad[0], quad[3], quad[2], quad[1]]  # same diagonal 0-2, opposite winding
    assert ok(flipped), "quad %r cannot be oriented by rule %r (non-convex or mis-ordered?)" % (quad, rule)
    return flipped


# --------------------------------------------------------------------------------------
# glTF writer
# --------------------------------------------------------------------------------------


class GltfBuilder:
    def __init__(self, extras):
        self.bin = bytearray()
        self.gltf = {
            "asset": {"version": "2.0", "generator": "hemirad make_scenes.py", "extras": extras},
            "scene": 0,
            "scenes": [{"name": "scene", "nodes": []}],
            "nodes": [],
            "meshes": [],
            "materials": [],
            "accessors": [],
            "bufferViews": [],
            "buffers": [],
        }
        self.material_index = {}
        self.uses_emissive_strength = False
        self.extensions = set()  # besides KHR_materials_emissive_strength
        self.lights = []  # KHR_lights_punctual

    def _align(self):
        while len(self.bin) % 4:
            self.bin.append(0)

    def _view(self, data, target):
        self._align()
        offset = len(self.bin)
        self.bin += data
        self.gltf["bufferViews"].append(
            {"buffer": 0, "byteOffset": offset, "byteLength": len(data), "target": target}
        )
        return len(self.gltf["bufferViews"]) - 1

    def material(self, name, base_color, emission=None, strength=None, double_sided=False):
        """emission: emissiveFactor (each in [0,1]); strength: KHR_materials_emissive_strength;
        double_sided: glTF doubleSided (both sides are surfaces: they emit and reflect)."""
        for c in base_color:
            assert 0.0 <= c <= 1.0
        m = {
            "name": name,
            "pbrMetallicRoughness": {
                "baseColorFactor": [float(c) for c in base_color] + [1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 1.0,
            },
            "doubleSided": bool(double_sided),
        }
        if emission is not None:
            for c in emission:
                assert 0.0 <= c <= 1.0
            m["emissiveFactor"] = [float(c) for c in emission]
            if strength is not None and strength != 1.0:
                m["extensions"] = {EMISSIVE_EXT: {"emissiveStrength": float(strength)}}
                self.uses_emissive_strength = True
        self.gltf["materials"].append(m)
        self.material_index[name] = len(self.gltf["materials"]) - 1
        return self.material_index[name]

    def texture(self, png, wrap=10497):
        """A texture of a PNG image (bytes, embedded as a data URI) through a sampler with
        wrap mode `wrap` both ways (10497 REPEAT, 33071 CLAMP_TO_EDGE); returns its index."""
        g = self.gltf
        g.setdefault("images", []).append({"uri": "data:image/png;base64," + base64.b64encode(png).decode("ascii")})
        g.setdefault("samplers", []).append({"wrapS": wrap, "wrapT": wrap})
        g.setdefault("textures", []).append({"source": len(g["images"]) - 1, "sampler": len(g["samplers"]) - 1})
        return len(g["textures"]) - 1

    def textures_of(self, name, base=None, emissive=None, mask_cutoff=None, scale=None):
        """Gives material `name` a base colour texture (with a KHR_texture_transform scale, if
        given), an emissive texture, and alphaMode MASK with that cutoff."""
        m = self.gltf["materials"][self.material_index[name]]
        if base is not None:
            info = {"index": base}
            if scale is not None:
                info["extensions"] = {"KHR_texture_transform": {"scale": [float(scale[0]), float(scale[1])]}}
                self.extensions.add("KHR_texture_transform")
            m["pbrMetallicRoughness"]["baseColorTexture"] = info
        if emissive is not None:
            m["emissiveTexture"] = {"index": emissive}
        if mask_cutoff is not None:
            m["alphaMode"] = "MASK"
            m["alphaCutoff"] = float(mask_cutoff)

    def mesh_node(self, name, quads, material, uv=None):
        """One node + one mesh + one primitive holding the given (already oriented) quads; with
        `uv` (a function of a corner's position) the quads get TEXCOORD_0."""
        positions = []
        triangles = []
        for q in quads:
            base = len(positions)
            positions.extend(q)
            for t in QUAD_TRIS:
                triangles.append(tuple(base + i for i in t))
        mesh = self.triangle_mesh(name, positions, triangles, material,
                                  uvs=None if uv is None else [uv(p) for p in positions])
        self.add_node({"name": name, "mesh": mesh})

    def triangle_mesh(self, name, positions, triangles, material, colors=None, uvs=None):
        """One mesh with one primitive of indexed triangles (already oriented, in the mesh's own
        frame) and, if given, per-vertex COLOR_0 (float RGB in [0, 1]); returns its index. A node
        places it (add_node, or a child of one)."""
        assert len(positions) <= 65535
        indices = [i for t in triangles for i in t]
        assert all(0 <= i < len(positions) for i in indices)

        pos_data = b"".join(struct.pack("<3f", *p) for p in positions)
        idx_data = struct.pack("<%dH" % len(indices), *indices)
        pos_view = self._view(pos_data, 34962)  # ARRAY_BUFFER
        idx_view = self._view(idx_data, 34963)  # ELEMENT_ARRAY_BUFFER

        p32 = [tuple(f32(c) for c in p) for p in positions]
        acc = self.gltf["accessors"]
        acc.append(
            {
                "bufferView": pos_view,
                "componentType": 5126,  # FLOAT
                "count": len(positions),
                "type": "VEC3",
                "min": [min(p[k] for p in p32) for k in range(3)],
                "max": [max(p[k] for p in p32) for k in range(3)],
            }
        )
        pos_acc = len(acc) - 1
        acc.append(
            {
                "bufferView": idx_view,
                "componentType": 5123,  # UNSIGNED_SHORT
                "count": len(indices),
                "type": "SCALAR",
            }
        )
        idx_acc = len(acc) - 1
        attributes = {"POSITION": pos_acc}
        if colors is not None:
            assert len(colors) == len(positions)
            assert all(0.0 <= c <= 1.0 for rgb in colors for c in rgb)
            col_view = self._view(b"".join(struct.pack("<3f", *c) for c in colors), 34962)
            acc.append({"bufferView": col_view, "componentType": 5126, "count": len(colors), "type": "VEC3"})
            attributes["COLOR_0"] = len(acc) - 1
        if uvs is not None:
            assert len(uvs) == len(positions)
            uv_view = self._view(b"".join(struct.pack("<2f", *t) for t in uvs), 34962)
            acc.append({"bufferView": uv_view, "componentType": 5126, "count": len(uvs), "type": "VEC2"})
            attributes["TEXCOORD_0"] = len(acc) - 1

        self.gltf["meshes"].append(
            {
                "name": name,
                "primitives": [
                    {
                        "attributes": attributes,
                        "indices": idx_acc,
                        "material": self.material_index[material],
                        "mode": 4,  # TRIANGLES
                    }
                ],
            }
        )
        return len(self.gltf["meshes"]) - 1

    def camera_node(self, node_name, camera_name, yfov, aspect, znear, translation, rotation=None):
        cams = self.gltf.setdefault("cameras", [])
        cams.append(
            {
                "name": camera_name,
                "type": "perspective",
                "perspective": {"yfov": yfov, "aspectRatio": aspect, "znear": znear},
            }
        )
        node = {"name": node_name, "camera": len(cams) - 1, "translation": [float(c) for c in translation]}
        if rotation is not None:
            node["rotation"] = [float(c) for c in rotation]
        self.add_node(node)

    def light_node(self, node_name, light, translation, rotation=None):
        """A node placing a KHR_lights_punctual light (a dict as the extension writes it)."""
        self.lights.append(light)
        node = {"name": node_name, "translation": [float(c) for c in translation],
                "extensions": {"KHR_lights_punctual": {"light": len(self.lights) - 1}}}
        if rotation is not None:
            node["rotation"] = [float(c) for c in rotation]
        self.add_node(node)

    def add_node(self, node, root=True):
        """Appends a node (a dict as glTF writes it); a root of the scene unless root is False
        (then some node names it among its children). Returns its index."""
        self.gltf["nodes"].append(node)
        index = len(self.gltf["nodes"]) - 1
        if root:
            self.gltf["scenes"][0]["nodes"].append(index)
        return index

    def write(self, path):
        self._align()
        used = sorted(self.extensions | ({EMISSIVE_EXT} if self.uses_emissive_strength else set()))
        if self.lights:
            used = sorted(set(used) | {"KHR_lights_punctual"})
            self.gltf["extensions"] = {"KHR_lights_punctual": {"lights": self.lights}}
        if used:
            self.gltf["extensionsUsed"] = used
        self.gltf["buffers"] = [
            {
                "byteLength": len(self.bin),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.bin)).decode("ascii"),
            }
        ]
        # Put the keys in a conventional order; everything else keeps insertion order.
        order = ["asset", "extensionsUsed", "extensions", "scene", "scenes", "nodes", "cameras", "meshes",
                 "materials", "textures", "samplers", "images", "accessors", "bufferViews", "buffers"]
        out = {k: self.gltf[k] for k in order if k in self.gltf}
        text = json.dumps(out, indent=2) + "\n"
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
        return path


# --------------------------------------------------------------------------------------
# self-check: read a written file back and verify it
# --------------------------------------------------------------------------------------


def quat_rotate(q, v):
    x, y, z, w = q
    u = (x, y, z)
    t = cross(u, v)
    t = (2 * t[0], 2 * t[1], 2 * t[2])
    c = cross(u, t)
    return (v[0] + w * t[0] + c[0], v[1] + w * t[1] + c[1], v[2] + w * t[2] + c[2])


def mat_mul(a, b):
    """4x4 matrices as lists of rows."""
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def node_matrix(node):
    """A glTF node's local transform (rows): its matrix (stored column-major), else T * R * S."""
    if "matrix" in node:
        m = node["matrix"]
        return [[m[4 * j + i] for j in range(4)] for i in range(4)]
    t = node.get("translation", [0.0, 0.0, 0.0])
    x, y, z, w = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    s = node.get("scale", [1.0, 1.0, 1.0])
    r = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    return [[r[i][0] * s[0], r[i][1] * s[1], r[i][2] * s[2], t[i]] for i in range(3)] + [[0.0, 0.0, 0.0, 1.0]]


def transform_point(m, p):
    return tuple(m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3] for i in range(3))


def det3(m):
    return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))


def axis_quat(axis, degrees):
    """Unit quaternion (x, y, z, w) of a turn about an axis."""
    a = unit(axis)
    h = math.radians(degrees) / 2.0
    return (a[0] * math.sin(h), a[1] * math.sin(h), a[2] * math.sin(h), math.cos(h))


def quat_mul(p, q):
    """The rotation q, then p."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return (pw * qx + px * qw + py * qz - pz * qy, pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw, pw * qw - px * qx - py * qy - pz * qz)


def world_transforms(g, roots):
    """{node index: world matrix} for every node under the given roots."""
    out = {}
    stack = [(i, [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]) for i in roots]
    while stack:
        index, parent = stack.pop()
        world = mat_mul(parent, node_matrix(g["nodes"][index]))
        out[index] = world
        stack.extend((c, world) for c in g["nodes"][index].get("children", []))
    return out


def load_and_check(path, rules, expect_camera=None, closed_groups=(), double_sided=()):
    """rules: node name -> orientation rule (every mesh node must have one).
    expect_camera: (node name, world position, world view direction, world up).
    closed_groups: lists of node names whose triangles together must form a closed,
    consistently oriented surface (every directed edge matched by its reverse exactly once)."""
    with open(path, "r", encoding="utf-8") as f:
        g = json.load(f)

    assert g["asset"]["version"] == "2.0"
    assert len(g["buffers"]) == 1
    prefix = "data:application/octet-stream;base64,"
    uri = g["buffers"][0]["uri"]
    assert uri.startswith(prefix)
    blob = base64.b64decode(uri[len(prefix):])
    assert len(blob) == g["buffers"][0]["byteLength"]

    if any(EMISSIVE_EXT in m.get("extensions", {}) for m in g["materials"]):
        assert EMISSIVE_EXT in g.get("extensionsUsed", [])
    for m in g["materials"]:
        assert m.get("doubleSided", False) is (m["name"] in double_sided), m["name"]
        for c in m["pbrMetallicRoughness"]["baseColorFactor"]:
            assert 0.0 <= c <= 1.0, (m["name"], c)
        for c in m.get("emissiveFactor", [0, 0, 0]):
            assert 0.0 <= c <= 1.0, (m["name"], c)

    def read_accessor(i):
        a = g["accessors"][i]
        v = g["bufferViews"][a["bufferView"]]
        start = v.get("byteOffset", 0) + a.get("byteOffset", 0)
        if a["componentType"] == 5126 and a["type"] == "VEC3":
            assert start % 4 == 0 and v["byteLength"] >= 12 * a["count"]
            flat = struct.unpack_from("<%df" % (3 * a["count"]), blob, start)
            data = [tuple(flat[3 * k:3 * k + 3]) for k in range(a["count"])]
            assert "min" in a and "max" in a, "POSITION accessor needs min/max"
            assert a["min"] == [min(p[k] for p in data) for k in range(3)]
            assert a["max"] == [max(p[k] for p in data) for k in range(3)]
            return data
        if a["componentType"] == 5123 and a["type"] == "SCALAR":
            assert start % 2 == 0 and v["byteLength"] >= 2 * a["count"]
            return list(struct.unpack_from("<%dH" % a["count"], blob, start))
        raise AssertionError("unexpected accessor %r" % a)

    def read_colors(i):
        a = g["accessors"][i]
        v = g["bufferViews"][a["bufferView"]]
        start = v.get("byteOffset", 0) + a.get("byteOffset", 0)
        assert a["componentType"] == 5126 and a["type"] == "VEC3" and v["byteLength"] >= 12 * a["count"]
        flat = struct.unpack_from("<%df" % (3 * a["count"]), blob, start)
        assert all(0.0 <= c <= 1.0 for c in flat)
        return a["count"]

    scene_nodes = g["scenes"][g["scene"]]["nodes"]
    world = world_transforms(g, scene_nodes)
    tris_by_node = {}
    for ni in sorted(world):
        node = g["nodes"][ni]
        if "mesh" not in node:
            continue
        # World positions; a mirroring transform (negative determinant) turns the winding over
        # (glTF 2.0, 3.7.2.1), so the front is then the clockwise side: swap to compare.
        m = world[ni]
        mirrored = det3(m) < 0.0
        name = node["name"]
        assert name in rules, "no orientation rule for node %r" % name
        tris = []
        for prim in g["meshes"][node["mesh"]]["primitives"]:
            assert prim.get("mode", 4) == 4
            pos = [transform_point(m, p) for p in read_accessor(prim["attributes"]["POSITION"])]
            if "COLOR_0" in prim["attributes"]:
                assert read_colors(prim["attributes"]["COLOR_0"]) == len(pos)
            idx = read_accessor(prim["indices"])
            assert len(idx) % 3 == 0 and all(0 <= i < len(pos) for i in idx)
            for k in range(0, len(idx), 3):
                a, b, c = (pos[idx[k]], pos[idx[k + 1]], pos[idx[k + 2]])
                if mirrored:
                    b, c = c, b
                n = tri_normal(a, b, c)
                assert check_rule(rules[name], n, mean([a, b, c])), (
                    "%s: triangle %d of node %r faces the wrong way (normal %r)" % (path, k // 3, name, n)
                )
                tris.append((a, b, c))
        tris_by_node[name] = tris
    assert set(tris_by_node) == set(rules), (sorted(tris_by_node), sorted(rules))

    outward = [(name,) for name, rule in rules.items() if rule[0] == "closed_outward"]
    for name, in outward:
        volume = sum(dot(t[0], cross(t[1], t[2])) for t in tris_by_node[name]) / 6.0
        assert volume > 0.0, "%s: node %r does not face out (enclosed volume %r)" % (path, name, volume)
    for group in list(closed_groups) + outward:
        edges = {}
        for name in group:
            for t in tris_by_node[name]:
                for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
                    edges[e] = edges.get(e, 0) + 1
        for (a, b), count in edges.items():
            assert count == 1 and edges.get((b, a), 0) == 1, "%s: group %r is not closed at edge %r-%r" % (
                path, group, a, b)

    if expect_camera is not None:
        cname, cpos, cdir, cup = expect_camera
        cams = [g["nodes"][i] for i in scene_nodes if g["nodes"][i].get("name") == cname]
        assert len(cams) == 1 and "camera" in cams[0]
        node = cams[0]
        q = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
        assert all(abs(node["translation"][k] - cpos[k]) < 1e-9 for k in range(3))
        d = quat_rotate(q, (0.0, 0.0, -1.0))  # glTF cameras look down local -Z
        u = quat_rotate(q, (0.0, 1.0, 0.0))
        assert dot(d, unit(cdir)) > 1.0 - 1e-9, d
        assert dot(u, unit(cup)) > 1.0 - 1e-9, u
        cam = g["cameras"][node["camera"]]
        assert cam["type"] == "perspective" and 0.0 < cam["perspective"]["yfov"] < math.pi

    return g


# --------------------------------------------------------------------------------------
# Scene 1: the Cornell box
# --------------------------------------------------------------------------------------

# Cornell Program of Computer Graphics, "Cornell Box Data",
# https://www.graphics.cornell.edu/online/box/data.html -- millimetres, Y up. Each quad is
# copied in the order published. (The published quads are not all exactly planar or
# rectangular -- e.g. the red wall -- and that is kept as is.)
CORNELL_MM = {
    "floor": [
        [(552.8, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 559.2), (549.6, 0.0, 559.2)],
    ],
    "light": [
        [(343.0, 548.8, 227.0), (343.0, 548.8, 332.0), (213.0, 548.8, 332.0), (213.0, 548.8, 227.0)],
    ],
    "ceiling": [
        [(556.0, 548.8, 0.0), (556.0, 548.8, 559.2), (0.0, 548.8, 559.2), (0.0, 548.8, 0.0)],
    ],
    "back_wall": [
        [(549.6, 0.0, 559.2), (0.0, 0.0, 559.2), (0.0, 548.8, 559.2), (556.0, 548.8, 559.2)],
    ],
    # "Right wall" in the data (green): x = 0, on the camera's right.
    "right_wall": [
        [(0.0, 0.0, 559.2), (0.0, 0.0, 0.0), (0.0, 548.8, 0.0), (0.0, 548.8, 559.2)],
    ],
    # "Left wall" in the data (red): x ~ 550, on the camera's left.
    "left_wall": [
        [(552.8, 0.0, 0.0), (549.6, 0.0, 559.2), (556.0, 548.8, 559.2), (556.0, 548.8, 0.0)],
    ],
    "short_block": [
        [(130.0, 165.0, 65.0), (82.0, 165.0, 225.0), (240.0, 165.0, 272.0), (290.0, 165.0, 114.0)],
        [(290.0, 0.0, 114.0), (290.0, 165.0, 114.0), (240.0, 165.0, 272.0), (240.0, 0.0, 272.0)],
        [(130.0, 0.0, 65.0), (130.0, 165.0, 65.0), (290.0, 165.0, 114.0), (290.0, 0.0, 114.0)],
        [(82.0, 0.0, 225.0), (82.0, 165.0, 225.0), (130.0, 165.0, 65.0), (130.0, 0.0, 65.0)],
        [(240.0, 0.0, 272.0), (240.0, 165.0, 272.0), (82.0, 165.0, 225.0), (82.0, 0.0, 225.0)],
    ],
    "tall_block": [
        [(423.0, 330.0, 247.0), (265.0, 330.0, 296.0), (314.0, 330.0, 456.0), (472.0, 330.0, 406.0)],
        [(423.0, 0.0, 247.0), (423.0, 330.0, 247.0), (472.0, 330.0, 406.0), (472.0, 0.0, 406.0)],
        [(472.0, 0.0, 406.0), (472.0, 330.0, 406.0), (314.0, 330.0, 456.0), (314.0, 0.0, 456.0)],
        [(314.0, 0.0, 456.0), (314.0, 330.0, 456.0), (265.0, 330.0, 296.0), (265.0, 0.0, 296.0)],
        [(265.0, 0.0, 296.0), (265.0, 330.0, 296.0), (423.0, 330.0, 247.0), (423.0, 0.0, 247.0)],
    ],
}

# Camera from the data: position (278, 273, -800) mm, direction (0, 0, 1), up (0, 1, 0),
# focal length 0.035 m, film 0.025 m x 0.025 m.
CORNELL_CAMERA_MM = (278.0, 273.0, -800.0)
CORNELL_FOCAL = 0.035
CORNELL_FILM = 0.025

# In the data the light is coplanar with the ceiling (y = 548.8). A coplanar emitter would
# z-fight with the ceiling, so it is lowered by 0.5 mm to y = 548.3.
CORNELL_LIGHT_DROP_MM = 0.5

MM = 0.001  # the file is written in metres (glTF's unit); hemirad itself is unit independent


def make_cornell(path):
    drop = CORNELL_LIGHT_DROP_MM
    data = {k: [[tuple(c for c in v) for v in q] for q in quads] for k, quads in CORNELL_MM.items()}
    data["light"] = [[(v[0], v[1] - drop, v[2]) for v in q] for q in data["light"]]
    assert all(v[1] == 548.3 for q in data["light"] for v in q)

    # Which wall is red: seen from the camera (looking +Z, up +Y, right-handed), the
    # camera's right is direction x up = (0,0,1) x (0,1,0) = (-1,0,0), so the x = 0 wall is
    # on the right (green) and the x ~ 550 wall is on the left (red), as the data says.
    cam_right = cross((0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
    assert cam_right == (-1.0, 0.0, 0.0)
    assert all(v[0] > 540.0 for q in data["left_wall"] for v in q)
    assert all(v[0] == 0.0 for q in data["right_wall"] for v in q)
    # The open side is the one facing the camera: z = 0 (the camera is at z = -800).
    assert CORNELL_CAMERA_MM[2] < 0.0

    # Convert to metres.
    data = {k: [[(v[0] * MM, v[1] * MM, v[2] * MM) for v in q] for q in quads] for k, quads in data.items()}

    # The room's interior reference point: the centre of the box's bounding volume.
    room = [v for k in ("floor", "ceiling", "back_wall", "left_wall", "right_wall") for q in data[k] for v in q]
    lo = [min(v[k] for v in room) for k in range(3)]
    hi = [max(v[k] for v in room) for k in range(3)]
    inside = tuple((lo[k] + hi[k]) / 2 for k in range(3))

    rules = {
        "floor": faces_towards(inside),
        "ceiling": faces_towards(inside),
        "back_wall": faces_towards(inside),
        "left_wall": faces_towards(inside),
        "right_wall": faces_towards(inside),
        "light": faces_direction((0.0, -1.0, 0.0)),
        "short_block": faces_away_from(mean([v for q in data["short_block"] for v in q])),
        "tall_block": faces_away_from(mean([v for q in data["tall_block"] for v in q])),
    }
    # Axis-aligned surfaces must also face along their exact axis.
    axis = {"floor": (0, 1, 0), "ceiling": (0, -1, 0), "back_wall": (0, 0, -1), "right_wall": (1, 0, 0)}

    b = GltfBuilder(
        {
            "title": "Cornell box",
            "source": "Cornell Program of Computer Graphics, Cornell Box Data, "
                      "https://www.graphics.cornell.edu/online/box/data.html",
            "units": "metres (the published data is in millimetres; every coordinate was multiplied by 0.001)",
            "changes": "light lowered by 0.5 mm (y 548.8 mm -> 548.3 mm) so it is not coplanar with the ceiling; "
                       "winding set so fronts face into the box and out of the blocks; "
                       "spectral data replaced by RGB reflectances and emission",
            "left_wall": "red, x ~ 0.55 m, on the camera's left",
            "right_wall": "green, x = 0, on the camera's right",
            "open_side": "z = 0 (facing the camera), left open as in the original",
            "emission": "light radiance (17, 12, 4) = emissiveFactor (1, 12/17, 4/17) x emissiveStrength 17",
        }
    )
    b.material("white", (0.725, 0.71, 0.68))
    b.material("red", (0.63, 0.065, 0.05))
    b.material("green", (0.14, 0.45, 0.091))
    b.material("light", (0.78, 0.78, 0.78), emission=(1.0, 12.0 / 17.0, 4.0 / 17.0), strength=17.0)

    nodes = [
        ("floor", "white"),
        ("ceiling", "white"),
        ("back_wall", "white"),
        ("left_wall", "red"),
        ("right_wall", "green"),
        ("light", "light"),
        ("short_block", "white"),
        ("tall_block", "white"),
    ]
    for name, mat in nodes:
        quads = [orient_quad(q, rules[name]) for q in data[name]]
        if name in axis:
            for q in quads:
                for t in QUAD_TRIS:
                    assert dot(tri_normal(*(q[i] for i in t)), axis[name]) > 0.9999, name
        b.mesh_node(name, quads, mat)

    yfov = 2.0 * math.atan((CORNELL_FILM / 2.0) / CORNELL_FOCAL)
    cam_pos = tuple(c * MM for c in CORNELL_CAMERA_MM)
    # glTF cameras look down local -Z; a 180 degree turn about +Y makes them look down +Z.
    b.camera_node("camera", "cornell", yfov, 1.0, 0.01, cam_pos, rotation=(0.0, 1.0, 0.0, 0.0))
    b.write(path)

    load_and_check(path, rules, expect_camera=("camera", cam_pos, (0, 0, 1), (0, 1, 0)))


# --------------------------------------------------------------------------------------
# Scene 2: a closed room
# --------------------------------------------------------------------------------------

ROOM_X, ROOM_Y, ROOM_Z = 4.0, 2.5, 5.0  # metres; x in [-2, 2], y in [0, 2.5], z in [-2.5, 2.5]


def box_faces(x0, x1, y0, y1, z0, z1):
    """The six faces of an axis-aligned box, as unoriented quads, by name."""
    return {
        "floor": [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],
        "ceiling": [(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)],
        "wall_north": [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)],  # z = z0 (north = -Z)
        "wall_south": [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],  # z = z1
        "wall_east": [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)],  # x = x1 (east = +X)
        "wall_west": [(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)],  # x = x0
    }


def make_room(path):
    hx, hz = ROOM_X / 2.0, ROOM_Z / 2.0
    shell = box_faces(-hx, hx, 0.0, ROOM_Y, -hz, hz)
    inside = (0.0, ROOM_Y / 2.0, 0.0)

    # 1 m x 1 m light panel, centred under the ceiling, 1 cm below it, facing down.
    ly = ROOM_Y - 0.01
    light = [(-0.5, ly, -0.5), (0.5, ly, -0.5), (0.5, ly, 0.5), (-0.5, ly, 0.5)]

    # 0.8 m cube standing on the floor, off-centre (towards the north-east), turned 20
    # degrees about Y. Five faces: the bottom would lie in the floor's plane and is never
    # seen, so it is left out (as the Cornell blocks have no bottom).
    s = 0.8
    cx, cz, turn = 0.8, -0.9, math.radians(20.0)
    ca, sa = math.cos(turn), math.sin(turn)

    def place(p):
        x, y, z = p
        return (cx + ca * x + sa * z, y, cz - sa * x + ca * z)

    cube_local = box_faces(-s / 2, s / 2, 0.0, s, -s / 2, s / 2)
    cube = [[place(v) for v in cube_local[k]] for k in ("ceiling", "wall_north", "wall_south", "wall_east", "wall_west")]
    cube_centre = (cx, s / 2.0, cz)
    # The cube must stand fully inside the room, clear of the walls.
    for q in cube:
        for v in q:
            assert -hx + 0.1 < v[0] < hx - 0.1 and -hz + 0.1 < v[2] < hz - 0.1

    rules = {name: faces_towards(inside) for name in shell}
    rules["light"] = faces_direction((0.0, -1.0, 0.0))
    rules["cube"] = faces_away_from(cube_centre)

    b = GltfBuilder(
        {
            "title": "Closed room",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres",
            "layout": "room 4 x 2.5 x 5 m (x, y, z): x in [-2, 2], y in [0, 2.5], z in [-2.5, 2.5]; "
                      "north = -Z, south = +Z, east = +X, west = -X",
            "light": "1 m x 1 m panel 1 cm below the ceiling centre, facing down, white emission x strength 10",
            "cube": "0.8 m, on the floor centred at (0.8, -0.9) in x, z, turned 20 degrees about Y; "
                    "five faces (no bottom)",
        }
    )
    b.material("wall_grey", (0.7, 0.7, 0.7))
    b.material("floor", (0.5, 0.45, 0.4))
    b.material("cube_grey", (0.5, 0.5, 0.5))
    b.material("light", (0.8, 0.8, 0.8), emission=(1.0, 1.0, 1.0), strength=10.0)

    for name in ("floor", "ceiling", "wall_north", "wall_south", "wall_east", "wall_west"):
        b.mesh_node(name, [orient_quad(shell[name], rules[name])], "floor" if name == "floor" else "wall_grey")
    b.mesh_node("light", [orient_quad(light, rules["light"])], "light")
    b.mesh_node("cube", [orient_quad(q, rules["cube"]) for q in cube], "cube_grey")

    # Camera 20 cm in front of the south wall, at 1.4 m, looking north (-Z, glTF's default
    # camera direction, so no rotation); the light panel, the cube and the far wall are in view.
    cam_pos = (0.0, 1.4, hz - 0.2)
    b.camera_node("camera", "room", 1.0, 4.0 / 3.0, 0.01, cam_pos)
    b.write(path)

    load_and_check(
        path,
        rules,
        expect_camera=("camera", cam_pos, (0, 0, -1), (0, 1, 0)),
        closed_groups=[("floor", "ceiling", "wall_north", "wall_south", "wall_east", "wall_west")],
    )


def make_empty_room(path):
    """The closed room without its cube, all grey, its light panel flush with the ceiling: a
    scene in which no surface can hide another and nothing is coloured (hemirad's effects
    planner then skips occlusion and solves one channel)."""
    hx, hz = ROOM_X / 2.0, ROOM_Z / 2.0
    shell = box_faces(-hx, hx, 0.0, ROOM_Y, -hz, hz)
    inside = (0.0, ROOM_Y / 2.0, 0.0)
    y = ROOM_Y
    # The ceiling is the four rectangles around the 1 m x 1 m light, all in the plane y = ROOM_Y.
    ceiling = [
        [(-hx, y, -hz), (-0.5, y, -hz), (-0.5, y, hz), (-hx, y, hz)],
        [(0.5, y, -hz), (hx, y, -hz), (hx, y, hz), (0.5, y, hz)],
        [(-0.5, y, -hz), (0.5, y, -hz), (0.5, y, -0.5), (-0.5, y, -0.5)],
        [(-0.5, y, 0.5), (0.5, y, 0.5), (0.5, y, hz), (-0.5, y, hz)],
    ]
    light = [(-0.5, y, -0.5), (0.5, y, -0.5), (0.5, y, 0.5), (-0.5, y, 0.5)]

    rules = {name: faces_towards(inside) for name in shell}
    rules["light"] = faces_direction((0.0, -1.0, 0.0))

    b = GltfBuilder(
        {
            "title": "Empty room",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres",
            "layout": "room 4 x 2.5 x 5 m (x, y, z): x in [-2, 2], y in [0, 2.5], z in [-2.5, 2.5]; "
                      "north = -Z, south = +Z, east = +X, west = -X",
            "light": "1 m x 1 m panel flush with the ceiling centre, facing down, white emission x strength 10",
            "purpose": "convex and grey: no surface hides another, every reflectance is grey",
        }
    )
    b.material("wall_grey", (0.7, 0.7, 0.7))
    b.material("floor_grey", (0.5, 0.5, 0.5))
    b.material("light", (0.8, 0.8, 0.8), emission=(1.0, 1.0, 1.0), strength=10.0)
    for name in ("floor", "wall_north", "wall_south", "wall_east", "wall_west"):
        b.mesh_node(name, [orient_quad(shell[name], rules[name])], "floor_grey" if name == "floor" else "wall_grey")
    b.mesh_node("ceiling", [orient_quad(q, rules["ceiling"]) for q in ceiling], "wall_grey")
    b.mesh_node("light", [orient_quad(light, rules["light"])], "light")

    cam_pos = (0.0, 1.4, hz - 0.2)
    b.camera_node("camera", "room", 1.0, 4.0 / 3.0, 0.01, cam_pos)
    b.write(path)
    load_and_check(path, rules, expect_camera=("camera", cam_pos, (0, 0, -1), (0, 1, 0)))


# --------------------------------------------------------------------------------------
# Real-shaped scenes (issue 20): curved double-sided meshes under nested node transforms, as
# Blender and Sketchfab export them. Meshes are triangle lists in their own frame, placed by
# nodes; every triangle is wound by a rule and checked again in world space after loading.
# --------------------------------------------------------------------------------------


def orient_triangle(positions, tri, rule):
    """tri (3 indices), reversed if needed so its front obeys `rule` (in the mesh's frame)."""
    a, b, c = (positions[i] for i in tri)
    if check_rule(rule, tri_normal(a, b, c), mean([a, b, c])):
        return tuple(tri)
    flipped = (tri[0], tri[2], tri[1])
    assert check_rule(rule, tri_normal(*(positions[i] for i in flipped)), mean([a, b, c]))
    return flipped


def cylinder_mesh(segments, stacks):
    """Radius 1, along y from -1 to 1: `stacks` bands of `segments` side quads (2 triangles
    each) and two caps fanned from a centre vertex (`segments` triangles each), facing out."""
    positions = []
    for k in range(stacks + 1):
        y = -1.0 + 2.0 * k / stacks
        for j in range(segments):
            a = 2.0 * math.pi * j / segments
            positions.append((math.cos(a), y, math.sin(a)))

    def at(k, j):
        return k * segments + j % segments

    triangles = []
    for k in range(stacks):
        for j in range(segments):
            quad = (at(k, j), at(k, j + 1), at(k + 1, j + 1), at(k + 1, j))
            for t in QUAD_TRIS:
                tri = tuple(quad[i] for i in t)
                y = mean([positions[i] for i in tri])[1]
                triangles.append(orient_triangle(positions, tri, faces_away_from((0.0, y, 0.0))))
    for k, y in ((0, -1.0), (stacks, 1.0)):
        centre = len(positions)
        positions.append((0.0, y, 0.0))
        for j in range(segments):
            triangles.append(orient_triangle(positions, (centre, at(k, j), at(k, j + 1)), faces_direction((0.0, y, 0.0))))
    return positions, triangles


def sphere_mesh(segments, rings):
    """Unit UV sphere, poles on y, polar bands fanned from the poles, facing out."""
    positions = [(0.0, 1.0, 0.0)]
    for b in range(1, rings):
        theta = math.pi * b / rings
        for j in range(segments):
            phi = 2.0 * math.pi * j / segments
            positions.append((math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi)))
    positions.append((0.0, -1.0, 0.0))
    south = len(positions) - 1

    def at(b, j):
        return 1 + (b - 1) * segments + j % segments

    out = faces_away_from((0.0, 0.0, 0.0))
    triangles = []
    for j in range(segments):
        triangles.append(orient_triangle(positions, (0, at(1, j), at(1, j + 1)), out))
        for b in range(1, rings - 1):
            quad = (at(b, j), at(b, j + 1), at(b + 1, j + 1), at(b + 1, j))
            for t in QUAD_TRIS:
                triangles.append(orient_triangle(positions, tuple(quad[i] for i in t), out))
        triangles.append(orient_triangle(positions, (at(rings - 1, j), at(rings - 1, j + 1), south), out))
    return positions, triangles


def torus_mesh(major, minor, tube):
    """A torus about y, tube centre radius 1, tube radius `tube`, facing out of the tube; the
    vertex (i, j) is at index i * minor + j (i around y, j around the tube)."""
    positions = []
    for i in range(major):
        u = 2.0 * math.pi * i / major
        for j in range(minor):
            v = 2.0 * math.pi * j / minor
            r = 1.0 + tube * math.cos(v)
            positions.append((r * math.cos(u), tube * math.sin(v), r * math.sin(u)))

    def at(i, j):
        return (i % major) * minor + j % minor

    triangles = []
    for i in range(major):
        u = 2.0 * math.pi * (i + 0.5) / major
        core = (math.cos(u), 0.0, math.sin(u))  # the tube's centre line at this quad
        for j in range(minor):
            quad = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1))
            for t in QUAD_TRIS:
                triangles.append(orient_triangle(positions, tuple(quad[k] for k in t), faces_away_from(core)))
    return positions, triangles


def look_at_quat(eye, target):
    """The rotation (x, y, z, w) of a glTF camera at `eye` (looking down its local -Z, +Y up)
    that looks at `target` with world +Y up."""
    d = unit(sub(target, eye))
    x = unit(cross(d, (0.0, 1.0, 0.0)))
    y = cross(x, d)
    z = (-d[0], -d[1], -d[2])
    m = [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]  # columns: the camera's axes
    w = math.sqrt(max(0.0, 1.0 + m[0][0] + m[1][1] + m[2][2])) / 2.0
    assert w > 0.1, "look_at_quat: a turn near 180 degrees"
    return ((m[2][1] - m[1][2]) / (4 * w), (m[0][2] - m[2][0]) / (4 * w), (m[1][0] - m[0][1]) / (4 * w), w)


def place(m, positions):
    return [transform_point(m, p) for p in positions]


def add_shell(b, rules, floor_material, wall_material, inside):
    """The closed room's six inward-facing walls, a node each."""
    hx, hz = ROOM_X / 2.0, ROOM_Z / 2.0
    shell = box_faces(-hx, hx, 0.0, ROOM_Y, -hz, hz)
    for name in ("floor", "ceiling", "wall_north", "wall_south", "wall_east", "wall_west"):
        rules[name] = faces_towards(inside)
        b.mesh_node(name, [orient_quad(shell[name], rules[name])], floor_material if name == "floor" else wall_material)
    return ("floor", "ceiling", "wall_north", "wall_south", "wall_east", "wall_west")


def assert_inside_room(points, clearance):
    hx, hz = ROOM_X / 2.0, ROOM_Z / 2.0
    for p in points:
        assert -hx + clearance < p[0] < hx - clearance and clearance < p[1] < ROOM_Y - clearance, p
        assert -hz + clearance < p[2] < hz - clearance, p


# The cylinder lamp: 28 segments, 2 stacks of side quads and two centre-fan caps: 112 + 56 = 168
# triangles; radius 0.15 m and 0.7 m long once its node scales it.
CYLINDER_SEGMENTS, CYLINDER_STACKS = 28, 2
CYLINDER_RADIUS, CYLINDER_HALF_LENGTH = 0.15, 0.35
CYLINDER_MOUNT = {"translation": [0.3, 1.3, -0.4], "rotation": list(quat_mul(axis_quat((0, 1, 0), 25.0),
                                                                            axis_quat((0, 0, 1), 35.0)))}
CYLINDER_NODE = {"rotation": list(axis_quat((1, 0, 0), 15.0)),
                 "scale": [CYLINDER_RADIUS, CYLINDER_HALF_LENGTH, CYLINDER_RADIUS]}


def make_double_sided_cylinder(path):
    """A 168-triangle double-sided emissive cylinder under a rotated parent and a rotated and
    scaled node, in the closed room, everything grey (rho 0.5)."""
    inside = (0.0, ROOM_Y / 2.0, 0.0)
    b = GltfBuilder(
        {
            "title": "Double-sided cylinder lamp",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres",
            "layout": "the closed room (4 x 2.5 x 5 m, x in [-2, 2], y in [0, 2.5], z in [-2.5, 2.5]), "
                      "every surface grey (reflectance 0.5)",
            "lamp": "a 28-segment cylinder (168 triangles: 2 stacks of side quads, centre-fan caps), radius "
                    "0.15 m, 0.7 m long, doubleSided, emission white x strength 5, reflectance 0.5; node "
                    "'cylinder' (turned 15 degrees about x, scaled 0.15, 0.35, 0.15) under 'lamp_mount' "
                    "(at (0.3, 1.3, -0.4), turned 35 degrees about z then 25 about y)",
            "purpose": "the configuration that crashed hemirad (stack overflow in point_to_polygon); in a "
                       "closed grey room the flux balance gives the sum of irradiance x area exactly",
        }
    )
    b.material("grey", (0.5, 0.5, 0.5))
    b.material("lamp", (0.5, 0.5, 0.5), emission=(1.0, 1.0, 1.0), strength=5.0, double_sided=True)
    rules = {}
    shell = add_shell(b, rules, "grey", "grey", inside)

    positions, triangles = cylinder_mesh(CYLINDER_SEGMENTS, CYLINDER_STACKS)
    assert len(triangles) == 168
    mesh = b.triangle_mesh("cylinder", positions, triangles, "lamp")
    child = b.add_node(dict(name="cylinder", mesh=mesh, **CYLINDER_NODE), root=False)
    b.add_node(dict(name="lamp_mount", children=[child], **CYLINDER_MOUNT))
    m = mat_mul(node_matrix(CYLINDER_MOUNT), node_matrix(CYLINDER_NODE))
    assert_inside_room(place(m, positions), 0.2)
    rules["cylinder"] = faces_away_from(transform_point(m, (0.0, 0.0, 0.0)))

    cam_pos = (0.0, 1.4, ROOM_Z / 2.0 - 0.2)
    b.camera_node("camera", "room", 1.0, 4.0 / 3.0, 0.01, cam_pos)
    b.write(path)
    load_and_check(path, rules, expect_camera=("camera", cam_pos, (0, 0, -1), (0, 1, 0)),
                   closed_groups=[shell, ("cylinder",)], double_sided=("lamp",))


# The lamp facing the sky: a 0.5 m square lamp 1 m above a 4 m square floor, nothing else.
SKY_FLOOR_HALF, SKY_LAMP_HALF, SKY_LAMP_HEIGHT, SKY_LAMP_GAP = 2.0, 0.25, 1.0, 0.001
SKY_LAMP_DIM, SKY_LAMP_BRIGHT = 1.0, 10.0


# The leaf canopy: small double-sided cards, none sharing an edge, scattered in a crown and on a
# lantern ring, in the closed room under its ceiling panel.
CANOPY_LEAVES, CANOPY_LEAF_SIDE, CANOPY_LEAF_TILT = 300, 0.08, 35.0
CANOPY_CENTRE, CANOPY_RADII = (-0.7, 1.3, -0.7), (0.75, 0.45, 0.75)
LANTERNS, LANTERN_SIDE, LANTERN_TILT = 48, 0.06, 20.0
LANTERN_CENTRE, LANTERN_RADIUS = (0.9, 0.9, 0.6), 0.35
GLOW_LEAVES, GLOW_LEAF_SIDE, GLOW_LEAF_TILT = 160, 0.06, 35.0
GLOW_CENTRE, GLOW_RADII = (1.2, 1.6, -1.9), (0.4, 0.3, 0.35)


def scattered_cards(rng, count, side, tilt, up, inside, placed, gap):
    """`count` square cards of edge `side` with random centres (inside(rng) draws one), at least
    `gap` from every centre in `placed` (so that no two touch), each facing `up` (+1 or -1 in y)
    tilted up to `tilt` degrees at a random azimuth and spun at random about its normal."""
    cards = []
    while len(cards) < count:
        c = inside(rng)
        if any(norm(sub(c, q)) < gap for q in placed):
            continue
        placed.append(c)
        theta, phi, spin = math.radians(tilt) * math.sqrt(rng.random()), 2 * math.pi * rng.random(), 2 * math.pi * rng.random()
        n = (math.sin(theta) * math.cos(phi), up * math.cos(theta), math.sin(theta) * math.sin(phi))
        a = unit(cross(n, (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 0.0, 1.0)))
        b = cross(n, a)
        u = tuple(math.cos(spin) * a[k] + math.sin(spin) * b[k] for k in range(3))
        v = cross(n, u)
        h = side / 2.0
        cards.append([tuple(c[k] + su * h * u[k] + sv * h * v[k] for k in range(3))
                      for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return cards


def in_ellipsoid(centre, radii):
    """A drawer of points uniform in the ellipsoid at `centre` with `radii` (for scattered_cards):
    draw(rng) rejects points of the unit cube outside the unit ball, then scales them."""
    def draw(r):
        while True:
            p = [2.0 * r.random() - 1.0 for _ in range(3)]
            if dot(p, p) <= 1.0:
                return tuple(centre[k] + radii[k] * p[k] for k in range(3))
    return draw


def make_leaf_canopy(path):
    """300 double-sided green leaf cards in a crown, 160 double-sided glowing leaf cards in a dense
    crown by the north-east walls and 48 double-sided emitting lantern cards on a ring, no two
    sharing an edge, in the closed room lit by its ceiling panel."""
    import random

    rng = random.Random(1)
    inside = (0.0, ROOM_Y / 2.0, 0.0)
    b = GltfBuilder(
        {
            "title": "Leaf canopy",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres",
            "layout": "the closed room (4 x 2.5 x 5 m, x in [-2, 2], y in [0, 2.5], z in [-2.5, 2.5]), walls "
                      "reflectance 0.7, floor (0.5, 0.45, 0.4), a 0.6 m ceiling panel (emission x 10) facing down",
            "leaves": "node 'leaves': 300 double-sided 8 cm square cards, reflectance (0.25, 0.55, 0.2), centred "
                      "in an ellipsoid at (-0.7, 1.3, -0.7) with radii (0.75, 0.45, 0.75), facing up tilted up to "
                      "35 degrees; centres at least 12 cm apart, so none touch",
            "lanterns": "node 'lanterns': 48 double-sided 6 cm cards emitting (1, 0.6, 0.3) x 3, reflectance 0.5, "
                        "on a 0.35 m ring around (0.9, 0.9, 0.6), heights 0.7 to 1.1 m, facing down tilted up to 20 "
                        "degrees",
            "glow": "node 'glow': 160 double-sided 6 cm cards emitting (1, 0.5, 0.2), reflectance (0.3, 0.5, 0.2), "
                    "centred in an ellipsoid at (1.2, 1.6, -1.9) with radii (0.4, 0.3, 0.35), 0.25 m from the north "
                    "wall, facing up tilted up to 35 degrees; centres at least 8.5 cm apart (a dense crown that "
                    "glows, as exported trees at night do)",
            "purpose": "many small faces of one material that share no edge (a tree's leaves, strings of lights), "
                       "which hemirad clusters across their gaps; a path-traced reference "
                       "(bench/reference/leaf_canopy) measures what that costs",
        }
    )
    b.material("wall_grey", (0.7, 0.7, 0.7))
    b.material("floor", (0.5, 0.45, 0.4))
    b.material("light", (0.8, 0.8, 0.8), emission=(1.0, 1.0, 1.0), strength=10.0)
    b.material("leaf", (0.25, 0.55, 0.2), double_sided=True)
    b.material("lantern", (0.5, 0.5, 0.5), emission=(1.0, 0.6, 0.3), strength=3.0, double_sided=True)
    b.material("glow", (0.3, 0.5, 0.2), emission=(1.0, 0.5, 0.2), double_sided=True)
    rules = {}
    hx, hz = ROOM_X / 2.0, ROOM_Z / 2.0
    shell = box_faces(-hx, hx, 0.0, ROOM_Y, -hz, hz)
    for name in ("floor", "ceiling", "wall_north", "wall_south", "wall_east", "wall_west"):
        rules[name] = faces_towards(inside)
        b.mesh_node(name, [orient_quad(shell[name], rules[name])], "floor" if name == "floor" else "wall_grey")
    ly, lh = ROOM_Y - 0.01, 0.3
    rules["light"] = faces_direction((0.0, -1.0, 0.0))
    b.mesh_node("light", [orient_quad([(-lh, ly, -lh), (lh, ly, -lh), (lh, ly, lh), (-lh, ly, lh)], rules["light"])],
                "light")

    def on_ring(r):
        a = 2 * math.pi * r.random()
        return (LANTERN_CENTRE[0] + LANTERN_RADIUS * math.cos(a), 0.7 + 0.4 * r.random(),
                LANTERN_CENTRE[2] + LANTERN_RADIUS * math.sin(a))

    placed = []
    rules["leaves"] = faces_half((0.0, 1.0, 0.0))
    leaves = scattered_cards(rng, CANOPY_LEAVES, CANOPY_LEAF_SIDE, CANOPY_LEAF_TILT, 1.0,
                             in_ellipsoid(CANOPY_CENTRE, CANOPY_RADII), placed, 0.12)
    b.mesh_node("leaves", [orient_quad(q, rules["leaves"]) for q in leaves], "leaf")
    rules["lanterns"] = faces_half((0.0, -1.0, 0.0))
    lanterns = scattered_cards(rng, LANTERNS, LANTERN_SIDE, LANTERN_TILT, -1.0, on_ring, placed, 0.09)
    b.mesh_node("lanterns", [orient_quad(q, rules["lanterns"]) for q in lanterns], "lantern")

    rules["glow"] = faces_half((0.0, 1.0, 0.0))
    glow = scattered_cards(rng, GLOW_LEAVES, GLOW_LEAF_SIDE, GLOW_LEAF_TILT, 1.0, in_ellipsoid(GLOW_CENTRE, GLOW_RADII),
                           placed, 0.085)
    b.mesh_node("glow", [orient_quad(q, rules["glow"]) for q in glow], "glow")
    assert_inside_room([v for q in leaves + lanterns + glow for v in q], 0.2)

    cam_pos = (0.0, 1.5, hz - 0.2)
    target = (0.0, 1.0, -0.5)
    b.camera_node("camera", "room", 1.0, 4.0 / 3.0, 0.01, cam_pos, rotation=look_at_quat(cam_pos, target))
    b.write(path)
    d = unit(sub(target, cam_pos))
    load_and_check(path, rules, expect_camera=("camera", cam_pos, d, cross(unit(cross(d, (0, 1, 0))), d)),
                   closed_groups=[("floor", "ceiling", "wall_north", "wall_south", "wall_east", "wall_west")],
                   double_sided=("leaf", "lantern", "glow"))


# The night street: two glowing tree crowns of emitting cards beside and over the roofs of two
# houses, and a string of lanterns between them; nothing else emits, nothing closes the sky.
STREET_HALF_X, STREET_HALF_Z = 12.0, 8.0
STREET_HOUSES = (  # name, x0, x1, z0, z1, height
    ("house_west", -9.0, -3.0, -7.0, -2.0, 4.0),
    ("house_east", 3.0, 9.0, -7.0, -2.0, 5.0),
)
STREET_CROWNS = (  # name, centre, radii, cards, emission, trunk top
    ("crown_pink", (0.0, 4.5, -4.5), (2.0, 1.5, 1.8), 200, (1.0, 0.45, 0.6), 2.6),
    ("crown_orange", (-6.0, 5.0, 0.5), (1.6, 1.2, 1.5), 160, (1.0, 0.6, 0.25), 3.4),
)
STREET_CARD, STREET_CARD_GAP, STREET_CARD_TILT = 0.25, 0.36, 35.0
STREET_LANTERNS, STREET_LANTERN_SIDE = 40, 0.12


def make_night_street(path):
    """Two houses on a street at night, lit only by two crowns of double-sided emitting leaf cards
    (no two sharing an edge) and a string of lantern cards: the exported city trees that glow at
    night, in the open."""
    import random

    rng = random.Random(7)
    b = GltfBuilder(
        {
            "title": "Night street",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres",
            "layout": "a 24 x 16 m ground (y = 0, facing up, reflectance (0.4, 0.38, 0.35)); two box houses, "
                      "walls (0.75, 0.7, 0.6), flat roofs (0.55, 0.3, 0.25), one-sided, no floor: 'house_west' "
                      "x in [-9, -3], z in [-7, -2], 4 m high, and 'house_east' x in [3, 9], 5 m high; open sky",
            "crowns": "node 'crown_pink': 200 double-sided 25 cm cards emitting (1, 0.45, 0.6) x 2, reflectance "
                      "(0.4, 0.3, 0.35), centred in an ellipsoid at (0, 4.5, -4.5) with radii (2, 1.5, 1.8) between "
                      "the houses, 1 m from each; 'crown_orange': 160 cards emitting (1, 0.6, 0.25) x 2 in an "
                      "ellipsoid at (-6, 5, 0.5), radii (1.6, 1.2, 1.5), over the street in front of the west "
                      "house's roof; cards face up tilted up to 35 degrees, centres at least 36 cm apart, so none "
                      "touch; a 30 cm square trunk under each (reflectance (0.35, 0.25, 0.15))",
            "lanterns": "node 'lanterns': 40 double-sided 12 cm cards emitting (1, 0.8, 0.5) x 6, reflectance 0.5, "
                        "on a sagging string from (-3, 3.6, -1.5) to (3, 4.4, -1.5)",
            "purpose": "the ww2 city's glowing trees by roofs and walls at night, in small: many emitting faces "
                       "of one material that share no edge, which hemirad clusters across their gaps; a "
                       "path-traced reference (bench/reference/night_street) measures what that costs",
        }
    )
    b.material("ground", (0.4, 0.38, 0.35))
    b.material("wall", (0.75, 0.7, 0.6))
    b.material("roof", (0.55, 0.3, 0.25))
    b.material("bark", (0.35, 0.25, 0.15))
    for name, _, _, _, emission, _ in STREET_CROWNS:
        b.material(name, (0.4, 0.3, 0.35), emission=emission, strength=2.0, double_sided=True)
    b.material("lantern", (0.5, 0.5, 0.5), emission=(1.0, 0.8, 0.5), strength=6.0, double_sided=True)
    rules = {"ground": faces_direction((0.0, 1.0, 0.0))}
    fx, fz = STREET_HALF_X, STREET_HALF_Z
    b.mesh_node("ground", [orient_quad([(-fx, 0.0, -fz), (fx, 0.0, -fz), (fx, 0.0, fz), (-fx, 0.0, fz)],
                                       rules["ground"])], "ground")
    solids = []  # boxes cards must keep clear of: (x0, x1, y0, y1, z0, z1)
    for name, x0, x1, z0, z1, height in STREET_HOUSES:
        faces = box_faces(x0, x1, 0.0, height, z0, z1)
        centre = ((x0 + x1) / 2.0, height / 2.0, (z0 + z1) / 2.0)
        rules[name] = rules[name + "_roof"] = faces_away_from(centre)
        b.mesh_node(name, [orient_quad(faces[f], rules[name])
                           for f in ("wall_north", "wall_south", "wall_east", "wall_west")], "wall")
        b.mesh_node(name + "_roof", [orient_quad(faces["ceiling"], rules[name])], "roof")
        solids.append((x0, x1, 0.0, height, z0, z1))

    placed, cards_all = [], []
    for name, centre, radii, count, _, trunk_top in STREET_CROWNS:
        h = 0.15
        trunk = box_faces(centre[0] - h, centre[0] + h, 0.0, trunk_top, centre[2] - h, centre[2] + h)
        rules[name + "_trunk"] = faces_away_from((centre[0], trunk_top / 2.0, centre[2]))
        b.mesh_node(name + "_trunk", [orient_quad(trunk[f], rules[name + "_trunk"])
                                      for f in ("ceiling", "wall_north", "wall_south", "wall_east", "wall_west")],
                    "bark")
        solids.append((centre[0] - h, centre[0] + h, 0.0, trunk_top, centre[2] - h, centre[2] + h))
        rules[name] = faces_half((0.0, 1.0, 0.0))
        cards = scattered_cards(rng, count, STREET_CARD, STREET_CARD_TILT, 1.0, in_ellipsoid(centre, radii), placed,
                                STREET_CARD_GAP)
        b.mesh_node(name, [orient_quad(q, rules[name]) for q in cards], name)
        cards_all += cards

    a, c = (-3.0, 3.6, -1.5), (3.0, 4.4, -1.5)

    def on_string(r):
        t = r.random()
        sag = 0.8 * 4.0 * t * (1.0 - t)
        return tuple(a[k] + t * (c[k] - a[k]) - (sag if k == 1 else 0.0) for k in range(3))

    rules["lanterns"] = faces_half((0.0, -1.0, 0.0))
    lanterns = scattered_cards(rng, STREET_LANTERNS, STREET_LANTERN_SIDE, 20.0, -1.0, on_string, placed, 0.12)
    b.mesh_node("lanterns", [orient_quad(q, rules["lanterns"]) for q in lanterns], "lantern")
    cards_all += lanterns
    # Every card clear of the houses and trunks (by 10 cm) and above the ground.
    for q in cards_all:
        for v in q:
            assert v[1] > 0.5
            for x0, x1, y0, y1, z0, z1 in solids:
                assert not (x0 - 0.1 < v[0] < x1 + 0.1 and y0 - 0.1 < v[1] < y1 + 0.1 and z0 - 0.1 < v[2] < z1 + 0.1)

    cam_pos = (1.5, 8.5, 9.5)
    target = (-1.0, 2.0, -3.0)
    b.camera_node("camera", "street", 1.0, 4.0 / 3.0, 0.05, cam_pos, rotation=look_at_quat(cam_pos, target))
    b.write(path)
    d = unit(sub(target, cam_pos))
    load_and_check(path, rules, expect_camera=("camera", cam_pos, d, cross(unit(cross(d, (0, 1, 0))), d)),
                   double_sided=tuple(n for n, *_ in STREET_CROWNS) + ("lantern",))


def make_lamp_facing_sky(path):
    """A lamp whose brighter side faces the open sky, above a floor: two one-sided squares back to
    back, 1 mm apart, the upper facing up (exitance 10), the lower facing the floor (exitance 1),
    neither reflecting."""
    f, h, g = SKY_FLOOR_HALF, SKY_LAMP_HALF, SKY_LAMP_GAP
    b = GltfBuilder(
        {
            "title": "Lamp facing the sky",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres",
            "layout": "a 4 x 4 m floor (y = 0, facing up, reflectance 0.5) and, 1 m above its centre, a "
                      "0.5 x 0.5 m lamp; no walls, no ceiling: open to the sky",
            "lamp": "node 'lamp' (at y = 1) holds 'lamp_down' (y = 0, facing the floor, exitance 1) and "
                    "'lamp_up' (1 mm above it, facing the sky, exitance 10 = emissiveFactor 1 x "
                    "emissiveStrength 10); both one-sided, reflectance 0",
            "purpose": "most of the light leaves for the sky; the floor is lit only by the dim side, "
                       "exactly E * F(point -> lamp) (nothing else reflects onto it)",
        }
    )
    b.material("floor", (0.5, 0.5, 0.5))
    b.material("lamp_dim", (0.0, 0.0, 0.0), emission=(SKY_LAMP_DIM,) * 3)
    b.material("lamp_bright", (0.0, 0.0, 0.0), emission=(1.0, 1.0, 1.0), strength=SKY_LAMP_BRIGHT)
    rules = {
        "floor": faces_direction((0.0, 1.0, 0.0)),
        "lamp_down": faces_direction((0.0, -1.0, 0.0)),
        "lamp_up": faces_direction((0.0, 1.0, 0.0)),
    }
    b.mesh_node("floor", [orient_quad([(-f, 0.0, -f), (f, 0.0, -f), (f, 0.0, f), (-f, 0.0, f)], rules["floor"])],
                "floor")
    children = []
    for name, y, material in (("lamp_down", 0.0, "lamp_dim"), ("lamp_up", g, "lamp_bright")):
        quad = orient_quad([(-h, y, -h), (h, y, -h), (h, y, h), (-h, y, h)], rules[name])
        mesh = b.triangle_mesh(name, quad, list(QUAD_TRIS), material)
        children.append(b.add_node({"name": name, "mesh": mesh}, root=False))
    b.add_node({"name": "lamp", "translation": [0.0, SKY_LAMP_HEIGHT, 0.0], "children": children})

    cam_pos = (0.0, 1.8, 3.2)
    target = (0.0, 0.4, 0.0)
    b.camera_node("camera", "side", 1.0, 4.0 / 3.0, 0.01, cam_pos, rotation=look_at_quat(cam_pos, target))
    b.write(path)
    d = unit(sub(target, cam_pos))
    load_and_check(path, rules, expect_camera=("camera", cam_pos, d, cross(unit(cross(d, (0, 1, 0))), d)))


# The curved objects: a double-sided, vertex-coloured torus and a one-sided sphere, both under
# mirroring node chains, in the closed room with its ceiling light.
TORUS_MAJOR, TORUS_MINOR, TORUS_TUBE, TORUS_SCALE = 24, 12, 0.35, 0.3
TORUS_COLOURS = ((0.9, 0.35, 0.2), (0.25, 0.5, 0.9))  # a checker of 2 x 2 vertex blocks
TORUS_RHO = 0.8
TORUS_STAND = {"rotation": list(axis_quat((0, 1, 0), 30.0)), "scale": [-1.0, 1.0, 1.0]}  # mirrors
TORUS_TILT = {"rotation": list(axis_quat((1, 0, 0), 70.0))}
BALL_SEGMENTS, BALL_RINGS, BALL_RADIUS, BALL_RHO = 24, 12, 0.3, 0.6
BALL_SHELF = {"translation": [-0.8, 0.35, 0.9], "rotation": list(axis_quat((1, 1, 0), 50.0)),
              "scale": [1.0, -1.0, 1.0]}  # mirrors


def make_curved_objects(path):
    inside = (0.0, ROOM_Y / 2.0, 0.0)
    b = GltfBuilder(
        {
            "title": "Curved objects under mirrored nodes",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres",
            "layout": "the closed room (4 x 2.5 x 5 m, x in [-2, 2], y in [0, 2.5], z in [-2.5, 2.5]): walls "
                      "and ceiling reflectance 0.7, floor (0.5, 0.45, 0.4), a 1 x 1 m ceiling light 1 cm below "
                      "the ceiling, facing down, white emission x strength 10 (reflectance 0.8)",
            "torus": "24 x 12 segments (576 triangles), tube radius 0.35 of the ring's, doubleSided, reflectance "
                     "0.8 x COLOR_0, a checker of (0.9, 0.35, 0.2) and (0.25, 0.5, 0.9); node 'torus' (scaled "
                     "0.3) under 'tilt' (70 degrees about x) under 'stand' (30 degrees about y, mirrored in x), "
                     "resting 2 cm above the floor",
            "ball": "a UV sphere (24 x 12), radius 0.3 m, one-sided, reflectance 0.6; node 'ball' (scaled 0.3, "
                    "turned 20 degrees about z) under 'shelf' (at (-0.8, 0.35, 0.9), 50 degrees about (1, 1, 0), "
                    "mirrored in y)",
            "purpose": "mirrored world transforms (negative determinants) must keep every front facing out",
        }
    )
    b.material("wall_grey", (0.7, 0.7, 0.7))
    b.material("floor", (0.5, 0.45, 0.4))
    b.material("light", (0.8, 0.8, 0.8), emission=(1.0, 1.0, 1.0), strength=10.0)
    b.material("ceramic", (TORUS_RHO,) * 3, double_sided=True)
    b.material("ball_grey", (BALL_RHO,) * 3)
    rules = {}
    shell = add_shell(b, rules, "floor", "wall_grey", inside)
    ly = ROOM_Y - 0.01
    rules["light"] = faces_direction((0.0, -1.0, 0.0))
    b.mesh_node("light", [orient_quad([(-0.5, ly, -0.5), (0.5, ly, -0.5), (0.5, ly, 0.5), (-0.5, ly, 0.5)],
                                      rules["light"])], "light")

    positions, triangles = torus_mesh(TORUS_MAJOR, TORUS_MINOR, TORUS_TUBE)
    colours = [TORUS_COLOURS[(i // 2 + j // 2) % 2] for i in range(TORUS_MAJOR) for j in range(TORUS_MINOR)]
    torus = b.triangle_mesh("torus", positions, triangles, "ceramic", colors=colours)
    torus_node = {"scale": [TORUS_SCALE] * 3}
    # Stand the torus 2 cm above the floor, at (0.7, z = -0.6).
    local = mat_mul(mat_mul(node_matrix(TORUS_STAND), node_matrix(TORUS_TILT)), node_matrix(torus_node))
    lift = 0.02 - min(p[1] for p in place(local, positions))
    stand = dict(TORUS_STAND, translation=[0.7, lift, -0.6])
    m = mat_mul(mat_mul(node_matrix(stand), node_matrix(TORUS_TILT)), node_matrix(torus_node))
    assert det3(m) < 0.0
    assert_inside_room(place(m, positions), 0.019)
    t = b.add_node(dict(name="torus", mesh=torus, **torus_node), root=False)
    tilt = b.add_node(dict(name="tilt", children=[t], **TORUS_TILT), root=False)
    b.add_node(dict(name="stand", children=[tilt], **stand))
    rules["torus"] = closed_outward()

    positions, triangles = sphere_mesh(BALL_SEGMENTS, BALL_RINGS)
    ball = b.triangle_mesh("ball", positions, triangles, "ball_grey")
    ball_node = {"rotation": list(axis_quat((0, 0, 1), 20.0)), "scale": [BALL_RADIUS] * 3}
    m = mat_mul(node_matrix(BALL_SHELF), node_matrix(ball_node))
    assert det3(m) < 0.0
    assert_inside_room(place(m, positions), 0.04)
    child = b.add_node(dict(name="ball", mesh=ball, **ball_node), root=False)
    b.add_node(dict(name="shelf", children=[child], **BALL_SHELF))
    rules["ball"] = faces_away_from(transform_point(m, (0.0, 0.0, 0.0)))

    cam_pos = (0.0, 1.4, ROOM_Z / 2.0 - 0.2)
    b.camera_node("camera", "room", 1.0, 4.0 / 3.0, 0.01, cam_pos)
    b.write(path)
    load_and_check(path, rules, expect_camera=("camera", cam_pos, (0, 0, -1), (0, 1, 0)),
                   closed_groups=[shell, ("ball",)], double_sided=("ceramic",))


def png_rgba(width, height, texel):
    """A PNG of 8-bit RGBA texels, texel(x, y) -> (r, g, b, a), row 0 at the top."""
    raw = b"".join(b"\x00" + b"".join(bytes(texel(x, y)) for x in range(width)) for y in range(height))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")


def make_lit_room(path):
    """The closed room lit by punctual lights, with textures: see scenes/README.md."""
    hx, hz = ROOM_X / 2.0, ROOM_Z / 2.0
    inside = (0.0, ROOM_Y / 2.0, 0.0)
    rules = {}
    b = GltfBuilder(
        {
            "title": "Lit room",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres; light intensities in candela",
            "layout": "the closed room's shell; a checkered floor (texture repeated 4 x 5 times by "
                      "KHR_texture_transform), a warm point light, a cool spot light through an alpha-masked "
                      "card of round holes onto the north wall, an emissive sign on the west wall",
        }
    )
    b.material("wall_grey", (0.7, 0.7, 0.7))
    b.material("floor", (0.8, 0.8, 0.8))
    b.material("card", (0.3, 0.5, 0.2), double_sided=True)
    b.material("sign", (0.2, 0.2, 0.2), emission=(1.0, 0.45, 0.15), strength=6.0)
    # 2 x 2 checks of light and dark wood-ish tones per texture repeat.
    checks = png_rgba(16, 16, lambda x, y: (200, 180, 150, 255) if (x // 8 + y // 8) % 2 == 0 else (90, 70, 55, 255))
    b.textures_of("floor", base=b.texture(checks), scale=(ROOM_X, ROOM_Z))
    # A card of round holes: alpha 0 inside circles of radius 0.3 (in cells of a 4 x 4 grid).
    holes = png_rgba(64, 64, lambda x, y: (80, 130, 50, 0 if ((x % 16) - 7.5) ** 2 + ((y % 16) - 7.5) ** 2 < 30 else 255))
    b.textures_of("card", base=b.texture(holes, wrap=33071), mask_cutoff=0.5)
    # The sign's atlas: three lit letters' worth of blocks on black, 5% of the texels.
    def sign_texel(x, y):
        lit = 8 <= y < 24 and any(x0 <= x < x0 + 6 for x0 in (10, 28, 46)) and (x + y) % 5 != 0
        return (255, 255, 255, 255) if lit else (0, 0, 0, 255)
    b.textures_of("sign", emissive=b.texture(png_rgba(64, 32, sign_texel), wrap=33071))

    shell = box_faces(-hx, hx, 0.0, ROOM_Y, -hz, hz)
    for name in ("floor", "ceiling", "wall_north", "wall_south", "wall_east", "wall_west"):
        rules[name] = faces_towards(inside)
        quad = orient_quad(shell[name], rules[name])
        if name == "floor":
            b.mesh_node(name, [quad], "floor", uv=lambda p: ((p[0] + hx) / ROOM_X, (p[2] + hz) / ROOM_Z))
        else:
            b.mesh_node(name, [quad], "wall_grey")
    # The card: 0.8 m x 0.8 m, upright in the plane z = 0.4 in the spot's beam, its lower edge 0.9 m
    # up: its holes cast a pattern three times their size onto the north wall.
    card = [(0.5, 0.9, 0.4), (1.3, 0.9, 0.4), (1.3, 1.7, 0.4), (0.5, 1.7, 0.4)]
    rules["card"] = faces_direction((0.0, 0.0, 1.0))
    b.mesh_node("card", [orient_quad(card, rules["card"])], "card", uv=lambda p: ((p[0] - 0.5) / 0.8, (1.7 - p[1]) / 0.8))
    # The sign: 1.6 m x 0.8 m, 1 cm in front of the west wall, facing east.
    x = -hx + 0.01
    sign = [(x, 1.0, -1.6), (x, 1.0, -0.0), (x, 1.8, -0.0), (x, 1.8, -1.6)]
    rules["sign"] = faces_direction((1.0, 0.0, 0.0))
    b.mesh_node("sign", [orient_quad(sign, rules["sign"])], "sign", uv=lambda p: ((p[2] + 1.6) / 1.6, (1.8 - p[1]) / 0.8))

    b.light_node("bulb", {"name": "bulb", "type": "point", "color": [1.0, 0.85, 0.7], "intensity": 12.0},
                 (-1.0, 2.1, 0.8))
    spot_at, spot_to = (0.9, 1.3, 1.8), (0.9, 1.3, -2.5)
    b.light_node("spot", {"name": "spot", "type": "spot", "color": [0.75, 0.85, 1.0], "intensity": 60.0,
                          "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.35}},
                 spot_at, look_at_quat(spot_at, spot_to))
    cam_pos = (0.0, 1.4, hz - 0.2)
    b.camera_node("camera", "room", 1.0, 4.0 / 3.0, 0.01, cam_pos)
    b.write(path)
    load_and_check(path, rules, expect_camera=("camera", cam_pos, (0, 0, -1), (0, 1, 0)),
                   closed_groups=[("floor", "ceiling", "wall_north", "wall_south", "wall_east", "wall_west")],
                   double_sided=("card",))


def make_atrium(path):
    """A room open to the sky through its roof, lit by the sun: see scenes/README.md."""
    h, height, opening = 3.0, 4.0, 1.0
    inside = (0.0, height / 2.0, 0.0)
    rules = {}
    b = GltfBuilder(
        {
            "title": "Atrium",
            "source": "procedural (scenes/make_scenes.py)",
            "units": "metres; the sun's illuminance in lux",
            "layout": "room 6 x 4 x 6 m (x, y, z): x, z in [-3, 3], y in [0, 4]; its roof has a 2 m x 2 m "
                      "opening over the centre. The sun (azimuth 200 degrees, elevation 60 degrees, 10 lux) "
                      "shines through it onto the floor and the north wall; a 0.6 m block stands in that "
                      "patch. North = -Z, east = +X",
        }
    )
    b.material("plaster", (0.75, 0.72, 0.68))
    b.material("stone", (0.55, 0.5, 0.45))
    b.material("block", (0.6, 0.25, 0.2))
    shell = box_faces(-h, h, 0.0, height, -h, h)
    for name in ("floor", "wall_north", "wall_south", "wall_east", "wall_west"):
        rules[name] = faces_towards(inside)
        b.mesh_node(name, [orient_quad(shell[name], rules[name])], "stone" if name == "floor" else "plaster")
    # The roof: four one-sided quads around the opening, facing down into the room (their backs,
    # outside, stop the sun).
    y = height
    roof = [
        [(-h, y, -h), (h, y, -h), (h, y, -opening), (-h, y, -opening)],
        [(-h, y, opening), (h, y, opening), (h, y, h), (-h, y, h)],
        [(-h, y, -opening), (-opening, y, -opening), (-opening, y, opening), (-h, y, opening)],
        [(opening, y, -opening), (h, y, -opening), (h, y, opening), (opening, y, opening)],
    ]
    rules["roof"] = faces_direction((0.0, -1.0, 0.0))
    b.mesh_node("roof", [orient_quad(q, rules["roof"]) for q in roof], "plaster")
    # The sun's direction of travel, and where its light through the opening's centre meets the
    # floor: (0.79, -2.17) in x, z. The block stands there, five faces (no bottom).
    azimuth, elevation = math.radians(200.0), math.radians(60.0)
    towards = (math.sin(azimuth) * math.cos(elevation), math.sin(elevation), -math.cos(azimuth) * math.cos(elevation))
    travel = (-towards[0], -towards[1], -towards[2])
    s = 0.6
    bx, bz = 0.7, -1.6
    block = box_faces(bx - s / 2, bx + s / 2, 0.0, s, bz - s / 2, bz + s / 2)
    rules["block"] = faces_away_from((bx, s / 2, bz))
    b.mesh_node("block", [orient_quad(block[k], rules["block"])
                          for k in ("ceiling", "wall_north", "wall_south", "wall_east", "wall_west")], "block")
    b.light_node("sun", {"name": "sun", "type": "directional", "intensity": 10.0},
                 (0.0, height + 2.0, 0.0), look_at_quat((0.0, 0.0, 0.0), travel))
    cam_pos, cam_at = (2.8, 1.0, 2.8), (-0.6, 1.9, -2.2)  # from the south-east corner, up at the opening
    b.camera_node("camera", "atrium", math.radians(80.0), 4.0 / 3.0, 0.01, cam_pos, look_at_quat(cam_pos, cam_at))
    b.write(path)
    load_and_check(path, rules)


def main():
    for name, make in (
        ("cornell_box.gltf", make_cornell),
        ("closed_room.gltf", make_room),
        ("empty_room.gltf", make_empty_room),
        ("double_sided_cylinder.gltf", make_double_sided_cylinder),
        ("lamp_facing_sky.gltf", make_lamp_facing_sky),
        ("curved_objects.gltf", make_curved_objects),
        ("lit_room.gltf", make_lit_room),
        ("atrium.gltf", make_atrium),
        ("leaf_canopy.gltf", make_leaf_canopy),
        ("night_street.gltf", make_night_street),
    ):
        path = os.path.join(HERE, name)
        make(path)  # writes the file, reads it back and checks it (raises AssertionError on failure)
        print("wrote and checked", path)


if __name__ == "__main__":
    main()
