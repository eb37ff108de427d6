#!/usr/bin/env python3
"""Writes the malformed STL, PLY and glTF files of this corpus (one problem each).

Run from this directory: python3 make_mesh_corpus.py. tests/it/scene_formats/bad_files.rs
lists each file with the error it must give; the comments here say what each breaks.
"""
import json
import struct


def tri_bytes(points):
    return b"".join(struct.pack("<3f", *p) for p in points)


SQUARE = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 0, 0), (1, 1, 0), (0, 1, 0)]


def binary_stl(n_declared, triangles):
    body = b"".join(b"\0" * 12 + tri_bytes(t) + b"\0\0" for t in triangles)
    return b"x" * 80 + struct.pack("<I", n_declared) + body


def ascii_stl(facets):
    out = ["solid box"]
    for f in facets:
        out += ["facet normal 0 0 1", "outer loop"]
        out += ["vertex " + v for v in f]
        out += ["endloop", "endfacet"]
    out.append("endsolid box")
    return "\n".join(out) + "\n"


def write(name, data):
    mode = "wb" if isinstance(data, bytes) else "w"
    with open(name, mode) as f:
        f.write(data)


# Binary STL whose header declares 12 facets but holds 2 and a half.
write("stl_truncated.stl", binary_stl(12, [SQUARE[:3], SQUARE[3:]]) + b"\0" * 25)
# 40 bytes: neither an ASCII STL (no `solid`) nor long enough for a binary header.
write("stl_too_short.stl", b"\x01" * 40)
# ASCII STL with a NaN coordinate in its second facet.
write("stl_nan.stl", ascii_stl([["0 0 0", "1 0 0", "1 1 0"], ["0 0 0", "nan 1 0", "0 1 0"]]))
# ASCII STL whose second facet has a vertex with two coordinates.
write("stl_malformed.stl", ascii_stl([["0 0 0", "1 0 0", "1 1 0"], ["0 0 0", "1 1", "0 1 0"]]))
# ASCII STL with a second facet after `endsolid` (line 10): it was dropped.
write("stl_after_endsolid.stl", ascii_stl([["0 0 0", "1 0 0", "1 1 0"]])
      + ascii_stl([["0 0 0", "1 1 0", "0 1 0"]]).split("\n", 1)[1].replace("endsolid box\n", ""))

PLY_HEAD = ("ply\nformat {fmt} 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n"
            "property float z\nelement face {nf}\nproperty list uchar int vertex_indices\nend_header\n")
# Binary PLY declaring 4 vertices and 2 faces, cut off inside the third vertex.
write("ply_truncated.ply",
      PLY_HEAD.format(fmt="binary_little_endian", nv=4, nf=2).encode()
      + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 1, 1, 0)[:30])
# ASCII PLY declaring 3 faces and holding 2.
write("ply_wrong_count.ply", PLY_HEAD.format(fmt="ascii", nv=4, nf=3)
      + "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n")
# ASCII PLY whose second face names vertex 9 of 4.
write("ply_index.ply", PLY_HEAD.format(fmt="ascii", nv=4, nf=2)
      + "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 9\n")
# Binary PLY with a NaN coordinate (vertex 2, used by face 1); ASCII PLY parsers
# refuse `nan` as text already.
write("ply_nan.ply", PLY_HEAD.format(fmt="binary_little_endian", nv=4, nf=1).encode()
      + struct.pack("<12f", 0, 0, 0, float("nan"), 0, 0, 1, 1, 0, 0, 1, 0)
      + struct.pack("<B3i", 3, 0, 1, 2))
# ASCII PLY declaring 1 face and holding 2: the second was dropped without a word.
write("ply_face_count_short.ply", PLY_HEAD.format(fmt="ascii", nv=4, nf=2 - 1)
      + "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n")
# ASCII PLY whose third vertex has a fourth value (line 12): it was ignored.
write("ply_extra_value.ply", PLY_HEAD.format(fmt="ascii", nv=4, nf=2)
      + "0 0 0\n1 0 0\n1 1 0 7\n0 1 0\n3 0 1 2\n3 0 2 3\n")
# Binary PLY declaring 1 face and holding 2 (13 bytes each).
write("ply_binary_extra.ply", PLY_HEAD.format(fmt="binary_little_endian", nv=4, nf=1).encode()
      + struct.pack("<12f", 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0)
      + struct.pack("<B3i", 3, 0, 1, 2) + struct.pack("<B3i", 3, 0, 2, 3))
# A point cloud: vertices and no face element.
write("ply_points.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n")


def gltf(buffer, count=3, indices=None):
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "square", "mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": count,
                       "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
        "buffers": [buffer],
    }
    if indices is not None:
        doc["meshes"][0]["primitives"][0]["indices"] = 1
        doc["accessors"].append({"bufferView": 1, "componentType": 5123,
                                 "count": len(indices), "type": "SCALAR"})
        doc["bufferViews"].append({"buffer": 0, "byteOffset": 36, "byteLength": 2 * len(indices)})
    return json.dumps(doc, indent=1)


TRI = tri_bytes(SQUARE[:3])
# The .bin the buffer names does not exist.
write("gltf_missing_buffer.gltf", gltf({"byteLength": 36, "uri": "gltf_missing_buffer.bin"}))
# The .bin holds 24 of the 36 bytes byteLength declares.
write("gltf_short_buffer.gltf", gltf({"byteLength": 36, "uri": "gltf_short_buffer.bin"}))
write("gltf_short_buffer.bin", TRI[:24])
# The accessor claims 4 positions (48 bytes) in a 36-byte view.
write("gltf_accessor_range.gltf", gltf({"byteLength": 36, "uri": "gltf_accessor_range.bin"}, count=4))
write("gltf_accessor_range.bin", TRI)
# A NaN coordinate in the first triangle.
write("gltf_nan.gltf", gltf({"byteLength": 36, "uri": "gltf_nan.bin"}))
write("gltf_nan.bin", tri_bytes([(0, 0, 0), (float("nan"), 0, 0), (1, 1, 0)]))
# Indices 0 1 7 into 3 positions.
write("gltf_index.gltf", gltf({"byteLength": 42, "uri": "gltf_index.bin"}, indices=[0, 1, 7]))
write("gltf_index.bin", TRI + struct.pack("<3H", 0, 1, 7))
# Not JSON at all.
write("gltf_not_json.gltf", "this is not { json\n")
# A GLB header declaring 1000 bytes, cut off after 40.
write("glb_truncated.glb", b"glTF" + struct.pack("<II", 2, 1000) + struct.pack("<I", 200) + b"JSON"
      + b'{"asset":{"version":"2.0"}' + b" " * 6)
