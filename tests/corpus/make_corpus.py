#!/usr/bin/env python3
"""Generate tests/corpus: malformed scenes, each of which `hemirad bake` must answer with exit
code 2 and one line on stderr naming the file and the problem (tests/test_corpus.cpp).

    python3 tests/corpus/make_corpus.py

Python 3 standard library only; deterministic. Every case starts from one valid scene (a lamp
triangle over a floor quad, its buffer a base64 data URI) and breaks one thing. manifest.json
lists each file with a word its error line must contain.
"""

import base64
import copy
import json
import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))

# Floor quad (y = 0, facing +y) and a lamp triangle (y = 1, facing -y).
POSITIONS = [(-1, 0, -1), (-1, 0, 1), (1, 0, 1), (1, 0, -1), (-0.2, 1, -0.2), (0.2, 1, -0.2), (0, 1, 0.2)]
FLOOR = [0, 1, 2, 0, 2, 3]
LAMP = [4, 5, 6]


def buffer_bytes(positions=POSITIONS):
    data = b"".join(struct.pack("<3f", *p) for p in positions)
    data += b"".join(struct.pack("<H", i) for i in FLOOR + LAMP)
    while len(data) % 4:
        data += b"\0"
    return data


def base_scene(data=None):
    data = buffer_bytes() if data is None else data
    npos = len(POSITIONS)
    pos_bytes = 12 * npos
    return {
        "asset": {"version": "2.0", "generator": "hemirad tests/corpus/make_corpus.py"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"name": "floor", "mesh": 0}, {"name": "lamp", "mesh": 1}],
        "meshes": [
            {"name": "floor", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]},
            {"name": "lamp", "primitives": [{"attributes": {"POSITION": 0}, "indices": 2, "material": 1}]},
        ],
        "materials": [
            {"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0]}},
            {"name": "lamp", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]},
             "emissiveFactor": [1.0, 1.0, 1.0]},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": npos, "type": "VEC3",
             "min": [-1, 0, -1], "max": [1, 1, 1]},
            {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
            {"bufferView": 1, "byteOffset": 12, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": pos_bytes},
            {"buffer": 0, "byteOffset": pos_bytes, "byteLength": 18},
        ],
        "buffers": [{"byteLength": len(data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
    }


def dump(g):
    return json.dumps(g, indent=1, sort_keys=True) + "\n"


def cases():
    out = []  # (file name, contents (str or bytes), word the error must contain)
    good = dump(base_scene())
    out.append(("truncated.gltf", good[: len(good) // 2], "truncated.gltf"))
    out.append(("not_json.gltf", "this is not a glTF file\n", "not_json.gltf"))
    out.append(("empty_file.gltf", "", "empty_file.gltf"))

    g = base_scene(); g["asset"]["version"] = "1.0"
    out.append(("version_1.gltf", dump(g), "version"))

    g = base_scene(); g["buffers"][0]["uri"] = "missing.bin"
    out.append(("missing_buffer.gltf", dump(g), "missing.bin"))

    # A buffer that cannot be read: its uri names a directory (unreadable_buffer.bin/, kept in git
    # by the file inside it), which no permission bit can make readable, even to root.
    g = base_scene(); g["buffers"][0]["uri"] = "unreadable_buffer.bin"
    out.append(("unreadable_buffer.gltf", dump(g), "unreadable_buffer"))

    g = base_scene(); g["buffers"][0]["uri"] = "data:application/octet-stream;base64,@@@not base64@@@"
    out.append(("bad_data_uri.gltf", dump(g), "bad_data_uri.gltf"))

    g = base_scene(); g["accessors"][0]["count"] = 1000
    out.append(("accessor_past_view.gltf", dump(g), "accessor"))

    g = base_scene(); g["bufferViews"][1]["byteLength"] = 4000
    out.append(("view_past_buffer.gltf", dump(g), "past the end"))

    data = bytearray(buffer_bytes())
    struct.pack_into("<H", data, 12 * len(POSITIONS) + 2, 99)  # floor index 1 -> 99 (7 vertices)
    out.append(("index_out_of_range.gltf", dump(base_scene(bytes(data))), "index"))

    nan = list(POSITIONS); nan[2] = (math.nan, 0.0, 1.0)
    out.append(("nan_position.gltf", dump(base_scene(buffer_bytes(nan))), "nan_position.gltf"))
    inf = list(POSITIONS); inf[5] = (math.inf, 1.0, -0.2)
    out.append(("inf_position.gltf", dump(base_scene(buffer_bytes(inf))), "inf_position.gltf"))

    g = base_scene(); g["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [-0.5, 0.5, 0.5, 1.0]
    out.append(("negative_reflectance.gltf", dump(g), "baseColorFactor"))
    g = base_scene(); g["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [1.5, 0.5, 0.5, 1.0]
    out.append(("reflectance_above_1.gltf", dump(g), "baseColorFactor"))
    g = base_scene(); g["materials"][1]["emissiveFactor"] = [-1.0, 1.0, 1.0]
    out.append(("negative_emission.gltf", dump(g), "emissive"))
    g = base_scene(); del g["materials"][1]["emissiveFactor"]
    out.append(("no_emitters.gltf", dump(g), "emits"))

    g = base_scene(); g["scenes"][0]["nodes"] = []
    out.append(("no_geometry.gltf", dump(g), "no_geometry.gltf"))
    g = base_scene()
    for m in g["meshes"]:
        for p in m["primitives"]:
            p["mode"] = 1  # LINES
    out.append(("only_lines.gltf", dump(g), "only_lines.gltf"))

    g = base_scene(); g["accessors"][0]["count"] = 4000000000
    out.append(("huge_count.gltf", dump(g), "huge_count.gltf"))
    g = base_scene(); g["buffers"][0]["byteLength"] = 2 ** 62
    out.append(("huge_buffer.gltf", dump(g), "huge_buffer.gltf"))

    out.append(("bad_magic.glb", b"glTX" + struct.pack("<II", 2, 12), "bad_magic.glb"))
    glb_json = dump(base_scene()).encode()
    while len(glb_json) % 4:
        glb_json += b" "
    glb = b"glTF" + struct.pack("<II", 2, 12 + 8 + len(glb_json)) + struct.pack("<I", len(glb_json)) + b"JSON" + glb_json
    out.append(("truncated.glb", glb[: len(glb) // 2], "truncated.glb"))

    # Hostile files: made to overflow the stack, crash on no data, or be read whole before refused.
    out.append(("empty.glb", b"", "empty"))
    deep = good.replace("{", '{"extras": ' + "[" * 20000 + "]" * 20000 + ", ", 1)
    out.append(("deep_nesting.gltf", deep, "512 levels"))
    out.append(("deep_nesting.glb", glb_of(deep.encode()), "512 levels"))
    header = glb_of(glb_json)
    out.append(("length_past_end.glb", header[:8] + struct.pack("<I", len(header) + 1000) + header[12:], "truncated"))
    out.append(("binary_zeros.gltf", bytes(64), "not JSON"))

    # Legal glTF no bake can use, and invalid cameras.
    g = base_scene(); g["materials"][1]["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": 1e100}}
    g["extensionsUsed"] = ["KHR_materials_emissive_strength"]
    out.append(("emission_too_strong.gltf", dump(g), "1e+100"))
    for name, key, value in (("camera_aspect_negative.gltf", "aspectRatio", -1.0), ("camera_yfov_zero.gltf", "yfov", 0.0)):
        g = base_scene()
        g["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01}}]
        g["cameras"][0]["perspective"][key] = value
        g["nodes"].append({"name": "camera", "camera": 0, "translation": [0, 0.5, 3]})
        g["scenes"][0]["nodes"].append(2)
        out.append((name, dump(g), key))

    # Textures whose image cannot be used: under --strict-textures, exit 2 naming the image (without
    # it they bake with the material's factors and a warning).
    def textured(image):
        g = base_scene()
        g["images"] = [image]
        g["textures"] = [{"source": 0}] if image else [{}]
        if not image:
            del g["images"]
        g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
        return dump(g)
    strict = ["--strict-textures"]
    out.append(("missing_texture.gltf", textured({"uri": "missing_texture.png"}), "missing_texture.png", strict))
    out.append(("undecodable_texture.gltf", textured({"uri": "undecodable_texture.png"}), "undecodable_texture.png",
                strict))
    out.append(("texture_without_source.gltf", textured(None), "texture 0", strict))

    # Compressed geometry whose data does not decode (bytes no encoder writes), or whose
    # extension names what cannot be: exit 2 naming the bufferView or the primitive.
    garbage = bytes([0xff] * 64)
    def compressed(mode="ATTRIBUTES"):
        g = base_scene()
        g["buffers"].append({"byteLength": len(garbage),
                             "uri": "data:application/octet-stream;base64," + base64.b64encode(garbage).decode()})
        g["bufferViews"][0]["byteStride"] = 12
        g["bufferViews"][0]["extensions"] = {"EXT_meshopt_compression": {
            "buffer": 1, "byteLength": len(garbage), "byteStride": 12, "count": len(POSITIONS), "mode": mode}}
        g["extensionsUsed"] = g["extensionsRequired"] = ["EXT_meshopt_compression"]
        return dump(g)
    out.append(("meshopt_garbage.gltf", compressed(), "do not decode"))
    out.append(("meshopt_unknown_mode.gltf", compressed("POINTS"), "unknown mode"))
    g = base_scene()
    g["buffers"].append({"byteLength": len(garbage),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(garbage).decode()})
    g["bufferViews"].append({"buffer": 1, "byteLength": len(garbage)})
    g["meshes"][0]["primitives"][0]["extensions"] = {"KHR_draco_mesh_compression": {
        "bufferView": 2, "attributes": {"POSITION": 0}}}
    g["extensionsUsed"] = g["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    out.append(("draco_garbage.gltf", dump(g), "does not decode"))

    # Small files that ask for more than any machine holds, refused from their JSON (issue 42):
    # one index accessor of the floor's 2 triangles 300 times in 600 primitives of one mesh, placed
    # by 3,000 nodes: 1.08e9 triangles (242 GB) in 64 KB.
    indices = b"".join(struct.pack("<3H", 0, 1, 2) + struct.pack("<3H", 0, 2, 3) for _ in range(300))
    data = buffer_bytes() + indices
    g = base_scene(data)
    g["bufferViews"].append({"buffer": 0, "byteOffset": len(buffer_bytes()), "byteLength": len(indices)})
    g["accessors"].append({"bufferView": 2, "componentType": 5123, "count": 1800, "type": "SCALAR"})
    g["meshes"][0]["primitives"] = [{"attributes": {"POSITION": 0}, "indices": 3, "material": 0}] * 600
    g["nodes"] = [{"mesh": 1}] + [{"mesh": 0}] * 3000
    g["scenes"][0]["nodes"] = list(range(len(g["nodes"])))
    out.append(("instanced_billions.gltf", json.dumps(g, separators=(",", ":")) + "\n", "1.08e+09 triangles after instancing"))
    # An integer past 32 bits in an extension hemirad reads: tinygltf would read 2^32 + 12 as 12.
    g = json.loads(compressed())
    g["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["byteStride"] = 2**32 + 12
    out.append(("meshopt_stride_past_32_bits.gltf", dump(g), "must fit in 32 bits"))
    # The only lamp cut away whole by alphaMode MASK: the bake would be black.
    g = base_scene()
    g["materials"][1].update({"alphaMode": "MASK", "alphaCutoff": 0.5})
    g["materials"][1]["pbrMetallicRoughness"]["baseColorFactor"] = [0.0, 0.0, 0.0, 0.2]
    out.append(("lamp_masked_away.gltf", dump(g), "cut away by alphaMode MASK"))
    return out


def glb_of(json_bytes):
    while len(json_bytes) % 4:
        json_bytes += b" "
    return b"glTF" + struct.pack("<II", 2, 12 + 8 + len(json_bytes)) + struct.pack("<I", len(json_bytes)) + b"JSON" + json_bytes


def main():
    os.makedirs(os.path.join(HERE, "unreadable_buffer.bin"), exist_ok=True)
    with open(os.path.join(HERE, "unreadable_buffer.bin", "README"), "w") as f:
        f.write("A directory where unreadable_buffer.gltf expects its buffer file.\n")
    # Not an image at all, under an image's name (undecodable_texture.gltf uses it).
    with open(os.path.join(HERE, "undecodable_texture.png"), "w") as f:
        f.write("This is text, not a PNG.\n")
    manifest = []
    for name, contents, word, *args in cases():
        path = os.path.join(HERE, name)
        mode = "wb" if isinstance(contents, bytes) else "w"
        with open(path, mode) as f:
            f.write(contents)
        manifest.append({"file": name, "error_contains": word, **({"args": args[0]} if args else {})})
    with open(os.path.join(HERE, "manifest.json"), "w") as f:
        f.write(json.dumps(manifest, indent=1) + "\n")
    print("wrote", len(manifest), "cases to", HERE)


if __name__ == "__main__":
    main()
