#!/usr/bin/env python3
"""Writes the seed corpus under tests/fuzz/corpus/<target>/: for every format a few small valid
files (tetrahedron, cube, quads, comments, the format's variants) and slightly broken ones
(truncated, bad index, NaN, wrong counts), and small scene files. Run once; the output is
committed. Re-running overwrites the seeds (files the fuzzers add to corpus dirs are kept)."""
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))

TET_V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
TET_F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
CUBE_V = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
CUBE_Q = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]


def write(target, name, data):
    d = os.path.join(HERE, "corpus", target)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def obj():
    v = "".join(f"v {x} {y} {z}\n" for x, y, z in TET_V)
    write("obj", "tet.obj", "# tet\n" + v + "".join(f"f {a+1} {b+1} {c+1}\n" for a, b, c in TET_F))
    write("obj", "cube_quads.obj", "o cube\n" + "".join(f"v {x} {y} {z}\n" for x, y, z in CUBE_V)
          + "vn 0 0 1\nvt 0 0\ns off\n"
          + "".join("f " + " ".join(f"{i+1}/1/1" for i in q) + "\n" for q in CUBE_Q))
    write("obj", "negative_idx.obj", v + "f -4 -2 -3\nf -4 -3 -1\nf -4 -1 -2\nf -3 -2 -1\n")
    write("obj", "bad_index.obj", v + "f 1 2 9\n")
    write("obj", "nan.obj", "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    write("obj", "truncated.obj", v + "f 1 2")
    write("obj", "crlf_slashes.obj", v.replace("\n", "\r\n") + "f 1//1 3//1 2//1\r\nf 1/1 2/2 4/3\r\n")


def stl():
    facets = []
    for a, b, c in TET_F:
        facets.append([TET_V[a], TET_V[b], TET_V[c]])
    txt = "solid tet\n"
    for f in facets:
        txt += " facet normal 0 0 0\n  outer loop\n"
        txt += "".join(f"   vertex {x} {y} {z}\n" for x, y, z in f)
        txt += "  endloop\n endfacet\n"
    txt += "endsolid tet\n"
    write("stl", "tet_ascii.stl", txt)
    write("stl", "tet_ascii_truncated.stl", txt[: len(txt) // 2])
    write("stl", "ascii_bad_keyword.stl", txt.replace("endloop", "endlop", 1))

    def binary(header, fs, n=None):
        b = header.ljust(80, b"\0")[:80] + struct.pack("<I", len(fs) if n is None else n)
        for f in fs:
            b += struct.pack("<3f", 0, 0, 0)
            for p in f:
                b += struct.pack("<3f", *p)
            b += b"\0\0"
        return b

    write("stl", "tet_binary.stl", binary(b"binary tet", facets))
    write("stl", "binary_solid_header.stl", binary(b"solid but binary", facets))
    write("stl", "binary_count_too_big.stl", binary(b"x", facets, n=7))
    write("stl", "binary_nan.stl", binary(b"x", [[(float("nan"), 0, 0), (1, 0, 0), (0, 1, 0)]]))


def off():
    v = "".join(f"{x} {y} {z}\n" for x, y, z in TET_V)
    write("off", "tet.off", "OFF\n4 4 6\n" + v + "".join(f"3 {a} {b} {c}\n" for a, b, c in TET_F))
    write("off", "cube_quads.off", "OFF 8 6 12\n# cube\n"
          + "".join(f"{x} {y} {z}\n" for x, y, z in CUBE_V)
          + "".join("4 " + " ".join(map(str, q)) + " 255 0 0\n" for q in CUBE_Q))
    write("off", "coff.off", "COFF\n3 1 0\n0 0 0 1 1 1 1\n1 0 0 1 1 1 1\n0 1 0 1 1 1 1\n3 0 1 2\n")
    write("off", "bad_index.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n")
    write("off", "counts_too_big.off", "OFF\n400000 1 0\n0 0 0\n")
    write("off", "few_corners.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n")


def ply():
    head = ("ply\nformat {fmt} 1.0\ncomment tet\nelement vertex 4\nproperty float x\n"
            "property float y\nproperty float z\nelement face 4\n"
            "property list uchar int vertex_indices\nend_header\n")
    body = "".join(f"{x} {y} {z}\n" for x, y, z in TET_V) + "".join(
        f"3 {a} {b} {c}\n" for a, b, c in TET_F)
    write("ply", "tet_ascii.ply", head.format(fmt="ascii") + body)
    for fmt, e in (("binary_little_endian", "<"), ("binary_big_endian", ">")):
        b = head.format(fmt=fmt).encode()
        for p in TET_V:
            b += struct.pack(e + "3f", *p)
        for f in TET_F:
            b += struct.pack(e + "B3i", 3, *f)
        write("ply", f"tet_{fmt}.ply", b)
    write("ply", "extra_props.ply",
          "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
          "property double z\nproperty uchar red\nproperty list uchar float junk\n"
          "element face 1\nproperty list ushort uint vertex_index\nproperty int flags\n"
          "element edge 1\nproperty int a\nproperty int b\nend_header\n"
          "0 0 0 255 2 0.5 0.5\n1 0 0 0 0\n0 1 0 7 1 3\n3 0 1 2 9\n0 1\n")
    write("ply", "bad_index.ply", head.format(fmt="ascii") + body.replace("3 1 2 3", "3 1 2 30"))
    write("ply", "truncated_binary.ply", (head.format(fmt="binary_little_endian")).encode()
          + struct.pack("<3f", 0, 0, 0))
    write("ply", "no_end_header.ply", "ply\nformat ascii 1.0\nelement vertex 3\n")


def vtk():
    pts = " ".join(f"{x} {y} {z}" for x, y, z in TET_V)
    write("vtk", "tet_polydata.vtk", "# vtk DataFile Version 3.0\ntet\nASCII\nDATASET POLYDATA\n"
          f"POINTS 4 float\n{pts}\nPOLYGONS 4 16\n"
          + "".join(f"3 {a} {b} {c}\n" for a, b, c in TET_F)
          + "POINT_DATA 4\nSCALARS s float 1\nLOOKUP_TABLE default\n0 1 2 3\n")
    write("vtk", "tet_ugrid.vtk", "# vtk DataFile Version 2.0\ntet\nASCII\n"
          "DATASET UNSTRUCTURED_GRID\n"
          f"POINTS 4 double\n{pts}\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n")
    write("vtk", "strips_v5.vtk", "# vtk DataFile Version 5.1\nstrip\nASCII\nDATASET POLYDATA\n"
          f"POINTS 4 float\n{pts}\nTRIANGLE_STRIPS 1 4\nOFFSETS vtktypeint64\n0 4\n"
          "CONNECTIVITY vtktypeint64\n0 1 2 3\n")
    b = (b"# vtk DataFile Version 3.0\nbin\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n")
    for p in TET_V:
        b += struct.pack(">3f", *p)
    b += b"\nCELLS 1 5\n" + struct.pack(">5i", 4, 0, 1, 2, 3)
    b += b"\nCELL_TYPES 1\n" + struct.pack(">i", 10) + b"\n"
    write("vtk", "tet_binary.vtk", b)
    write("vtk", "bad_index.vtk", "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\n"
          f"POINTS 4 float\n{pts}\nPOLYGONS 1 4\n3 0 1 7\n")
    write("vtk", "type_count_mismatch.vtk", "# vtk DataFile Version 2.0\nx\nASCII\n"
          f"DATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n{pts}\nCELLS 1 5\n4 0 1 2 3\n"
          "CELL_TYPES 2\n10 5\n")


def msh():
    nodes = "".join(f"{i+1} {x} {y} {z}\n" for i, (x, y, z) in enumerate(TET_V))
    write("msh", "tet22.msh", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n" + nodes
          + "$EndNodes\n$Elements\n2\n1 15 2 0 1 1\n2 4 2 0 1 1 2 3 4\n$EndElements\n")
    write("msh", "tris22.msh", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n2 1 \"s\"\n"
          "$EndPhysicalNames\n$Nodes\n4\n" + nodes.replace("4 0 0 1", "40 0 0 1")
          + "$EndNodes\n$Elements\n4\n"
          + "".join(f"{k+1} 2 2 0 1 {a+1} {b+1} {c+1}\n".replace(" 4", " 40")
                    for k, (a, b, c) in enumerate(TET_F)) + "$EndElements\n")
    write("msh", "legacy10.msh", "$NOD\n4\n" + nodes + "$ENDNOD\n$ELM\n1\n1 4 1 1 4 1 2 3 4\n$ENDELM\n")
    write("msh", "gmsh4.msh", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n")
    write("msh", "unknown_node.msh", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n" + nodes
          + "$EndNodes\n$Elements\n1\n1 4 0 1 2 3 9\n$EndElements\n")
    write("msh", "truncated.msh", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n" + nodes[:20])


def scene():
    write("scene", "full.json", """{
  "name": "liver-lift",
  "organ": {"mesh": "phantom:liver", "scale": 1.0,
            "material": {"young": 5500, "poisson": 0.3, "density": 1000},
            "fixed": {"box": [[-1, -1, -1], [1, 1, -0.04]]}},
  "gravity": [0, 0, -9.81], "dt": 0.001, "duration": 1.0,
  "tools": [{"type": "grasper", "radius": 0.005,
             "trajectory": [{"t": 0.0, "pos": [0, 0, 0.05], "jaw": "open"},
                            {"t": 0.1, "pos": [0, 0, 0.05], "jaw": "closed"},
                            {"t": 0.6, "pos": [0, 0, 0.07], "jaw": "closed"}]}],
  "loads": [{"type": "point_force", "at": [0, 0, 0.05], "force": [0, 0, 2.0],
             "start": 0.0, "end": 1.0}],
  "models": [{"plugin": "pbd", "params": {"iterations": 10}},
             {"plugin": "fem_hex", "params": {"elements": 967}}],
  "reference": {"plugin": "reference_fem", "params": {}},
  "samples": {"nearest": [10, 50]},
  "compare_at": [0.5, 1.0],
  "output": {"surfaces": "every:10"}
}
""")
    write("scene", "minimal.json",
          '{"name": "m", "organ": {"mesh": "phantom:cube"}, "models": [{"plugin": "pbd"}]}\n')
    write("scene", "pin_head.json", """{"name": "pin", "organ": {"mesh": "meshes/steak.obj",
 "scale": 0.001, "repair": true, "fixed": {"vertices": [0, 1, 2]}},
 "loads": [{"type": "pin_head", "at": [0, 0, 0], "stiffness": 100,
            "path": [{"t": 0, "pos": [0, 0, 0]}, {"t": 1, "pos": [0, 0, 0.01]}]}],
 "tools": [{"type": "probe", "radius": 0.002, "trajectory": [{"t": 0, "pos": [0, 0, 0]}]}],
 "models": [{"plugin": "massspring", "model": "massspring", "label": "ms"}],
 "output": {"surfaces": "none"}}
""")
    write("scene", "unknown_key.json",
          '{"name": "u", "organ": {"mesh": "phantom:cube", "colour": 1}, "models": []}\n')
    write("scene", "bad_types.json",
          '{"name": 3, "organ": {"mesh": "phantom:cube"}, "dt": "fast", "models": [{"plugin": "pbd"}]}\n')
    write("scene", "bad_trajectory.json", """{"name": "t", "organ": {"mesh": "phantom:cube"},
 "tools": [{"type": "grasper", "trajectory": [{"t": 1, "pos": [0, 0]}, {"t": 0.5, "pos": [0, 0, 0], "jaw": "ajar"}]}],
 "models": [{"plugin": "pbd"}]}
""")
    write("scene", "not_json.json", '{"name": "x", "organ": {"mesh": "phantom:cube"},,]\n')


for f in (obj, stl, off, ply, vtk, msh, scene):
    f()
