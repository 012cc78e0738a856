#!/usr/bin/env python3
"""A synthetic deformbench results folder (no simulation): a UV sphere of radius 5 cm lifted at
its top by a grasp, for the report and viewer tests.

usage: synthetic_results.py OUT_DIR [--models K] [--frames F] [--rings R]

Writes OUT_DIR/results.json (deformbench-results/1 with "interaction"), rest_surface.obj and per
run final.obj plus a surfaces.pvd series of F frames (ASCII .vtp, as the harness writes them).
Run k lifts the top by (1 + 0.15 k) times the reference's lift; the last model is marked
invalid. Importable: sphere(), lifted() for in-memory tests.
"""
import json
import math
import os
import sys

import numpy as np


def sphere(rings):
    """UV sphere, radius 0.05 m: (V (n,3), F (m,3))."""
    segs = 2 * rings
    V = [[0, 0, 0.05]]
    for i in range(1, rings):
        th = math.pi * i / rings
        for j in range(segs):
            ph = 2 * math.pi * j / segs
            V.append([0.05 * math.sin(th) * math.cos(ph), 0.05 * math.sin(th) * math.sin(ph),
                      0.05 * math.cos(th)])
    V.append([0, 0, -0.05])
    F = []
    for j in range(segs):
        F.append([0, 1 + j, 1 + (j + 1) % segs])
    for i in range(rings - 2):
        a, b = 1 + i * segs, 1 + (i + 1) * segs
        for j in range(segs):
            j2 = (j + 1) % segs
            F.append([a + j, b + j, b + j2])
            F.append([a + j, b + j2, a + j2])
    last = len(V) - 1
    base = 1 + (rings - 2) * segs
    for j in range(segs):
        F.append([base + j, last, base + (j + 1) % segs])
    return np.array(V), np.array(F)


def lifted(V, amount, t_frac):
    """The sphere lifted near its top: a smooth bump of height amount * t_frac (m)."""
    w = np.exp(-np.sum((V - [0, 0, 0.05]) ** 2, axis=1) / (2 * 0.03 ** 2))
    out = V.copy()
    out[:, 2] += amount * t_frac * w
    out[:, 0] += 0.2 * amount * t_frac * w * np.sin(V[:, 1] * 60)
    return out


def fmt(x):
    return repr(float(x))


def write_vtp(path, X, F):
    s = ['<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian"'
         ' header_type="UInt64">\n<PolyData>\n<Piece NumberOfPoints="%d" NumberOfVerts="0" '
         'NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="%d">\n' % (len(X), len(F)),
         '<Points>\n<DataArray type="Float64" NumberOfComponents="3" format="ascii">\n']
    s += ["%s %s %s\n" % (fmt(a), fmt(b), fmt(c)) for a, b, c in X]
    s.append("</DataArray>\n</Points>\n<Polys>\n"
             '<DataArray type="Int64" Name="connectivity" format="ascii">\n')
    s += ["%d %d %d\n" % tuple(f) for f in F]
    s.append('</DataArray>\n<DataArray type="Int64" Name="offsets" format="ascii">\n')
    s += ["%d\n" % (3 * (i + 1)) for i in range(len(F))]
    s.append("</DataArray>\n</Polys>\n</Piece>\n</PolyData>\n</VTKFile>\n")
    with open(path, "w") as f:
        f.write("".join(s))


def write_obj(path, X, F):
    with open(path, "w") as f:
        f.write("".join("v %s %s %s\n" % (fmt(a), fmt(b), fmt(c)) for a, b, c in X))
        f.write("".join("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in F))


def main():
    args = sys.argv[1:]
    if not args:
        print(__doc__)
        return 2
    out = args[0]
    opt = lambda name, d: int(args[args.index(name) + 1]) if name in args else d
    models, frames, rings = opt("--models", 2), opt("--frames", 6), opt("--rings", 12)
    V, F = sphere(rings)
    os.makedirs(out, exist_ok=True)
    write_obj(os.path.join(out, "rest_surface.obj"), V, F)
    dt, steps = 0.001, 100 * max(frames - 1, 1)
    runs = []
    specs = [("reference_fem", "reference", 1.0)] + [
        ("model%d" % k, "model", 1.0 + 0.15 * (k + 1)) for k in range(models)]
    ref_final = lifted(V, 0.02, 1.0)
    for k, (name, role, gain) in enumerate(specs):
        label = "%s(gain=%g)" % (name, gain) if role == "model" else name
        folder = os.path.join(out, label.replace("(", "_").replace(")", "").replace("=", "_"))
        os.makedirs(folder, exist_ok=True)
        pvd = []
        for f in range(frames):
            X = lifted(V, 0.02 * gain, f / (frames - 1) if frames > 1 else 1.0)
            name_ = "surface_%06d.vtp" % (100 * f)
            if frames > 1:  # one frame: the final surface alone, as "output": "final" writes
                write_vtp(os.path.join(folder, name_), X, F)
            pvd.append('<DataSet timestep="%s" group="" part="0" file="%s"/>\n'
                       % (fmt(dt * 100 * f), name_))
        with open(os.path.join(folder, "surfaces.pvd"), "w") as fh:
            fh.write('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" '
                     'byte_order="LittleEndian">\n<Collection>\n%s</Collection>\n</VTKFile>\n'
                     % "".join(pvd))
        write_obj(os.path.join(folder, "final.obj"), X, F)
        rel = os.path.basename(folder)
        run = {"model": name, "plugin": name, "label": label, "role": role,
               "params": {"gain": gain} if role == "model" else {}, "status": "ok", "message": "",
               "steps": steps, "step_ms": {"median": 0.05 * (k + 1), "p95": 0.06 * (k + 1)},
               "final_surface": rel + "/final.obj"}
        if frames > 1:
            run["surface_series"] = rel + "/surfaces.pvd"
        if role == "model":
            e = np.linalg.norm(X - ref_final, axis=1)
            run["error"] = {"reference": "reference_fem", "rmse_all": float(np.sqrt((e ** 2).mean())),
                            "max": float(e.max())}
            run["valid"] = k < models
            if not run["valid"]:
                run["invalid_reason"] = "synthetic: marked invalid"
        runs.append(run)
    doc = {"format": "deformbench-results/1",
           "scene": {"name": "synthetic-lift", "file": "", "dt": dt, "duration": dt * steps,
                     "steps": steps},
           "organ": {"source": "synthetic sphere", "vertices": len(V), "triangles": len(F),
                     "rest_surface": "rest_surface.obj"},
           "interaction": {
               "fixed": {"boxes": [[[-1, -1, -1], [1, 1, -0.04]]], "surface_vertices": []},
               "tools": [{"type": "grasper", "radius": 0.01, "trajectory": [
                   {"t": 0.0, "pos": [0, 0, 0.05], "jaw": "closed"},
                   {"t": dt * steps, "pos": [0, 0, 0.07], "jaw": "closed"}]}],
               "loads": []},
           "runs": runs}
    with open(os.path.join(out, "results.json"), "w") as f:
        json.dump(doc, f, indent=1)
    print("synthetic results: %s (%d runs, %d vertices, %d frames)"
          % (out, len(runs), len(V), frames))
    return 0


if __name__ == "__main__":
    sys.exit(main())
