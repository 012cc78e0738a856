"""The interactive 3D viewer of a results folder: its data (quantised, compressed surfaces) and
its HTML (three.js from Debian's libjs-three, inlined: the page needs no network).

Encoding of a run's surface series (decoded by viewer/viewer.js):
  q = round((x - base) / scale) as int16, per axis scale = max |x - base| / 32767 over the run;
  base = the organ's rest surface (rest_surface.obj) or, without it, the run's first frame.
  Frames are stored as differences from the previous frame (int16, wrapping), each frame as its
  x block, y block, z block; the low bytes of the whole run come first, then the high bytes; the
  result is zlib-compressed and base64-encoded. The position error of the quantisation is at
  most scale / 2 per axis (a micrometre for a 6 cm displacement).
When the encoded series exceed the size budget, frames are thinned (every k-th, always the
last) and the viewer says so.
"""
import base64
import html
import json
import os
import re
import zlib

import numpy as np

THREE_JS = ["/usr/share/javascript/three/build/three.min.js"]
ORBIT_JS = ["/usr/share/javascript/three/examples/js/controls/OrbitControls.js"]
VIEWER_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "viewer")
# The encoded surfaces of one viewer; three.js and the page add about 0.7 MB.
BUDGET_BYTES = 28 * 1000 * 1000


def find_file(candidates, env):
    path = os.environ.get(env)
    if path:
        return path if os.path.isfile(path) else None
    return next((p for p in candidates if os.path.isfile(p)), None)


def viewer_assets():
    """(three.min.js text, OrbitControls.js text) or raises OSError naming what is missing."""
    three = find_file(THREE_JS, "DEFORM_THREE_JS")
    orbit = find_file(ORBIT_JS, "DEFORM_THREE_ORBIT_JS")
    if not three or not orbit:
        raise OSError("three.js not found (%s; Debian package libjs-three)" %
                      (THREE_JS[0] if not three else ORBIT_JS[0]))
    with open(three) as f:
        a = f.read()
    with open(orbit) as f:
        b = f.read()
    return a, b


def read_obj(path):
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                verts.append(line.split()[1:4])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) for t in line.split()[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                for k in range(1, len(idx) - 1):
                    faces.append((idx[0], idx[k], idx[k + 1]))
    return (np.array(verts, dtype=np.float64).reshape(-1, 3),
            np.array(faces, dtype=np.int64).reshape(-1, 3))


def read_vtp_points(path):
    with open(path) as f:
        text = f.read()
    at = text.index("<Points>")
    begin = text.index(">", text.index("<DataArray", at)) + 1
    end = text.index("</DataArray>", begin)
    return np.array(text[begin:end].split(), dtype=np.float64).reshape(-1, 3)


def read_pvd(path):
    with open(path) as f:
        text = f.read()
    out = []
    for attrs in re.findall(r"<DataSet\s([^>]*)>", text):
        t = re.search(r'timestep="([^"]*)"', attrs)
        fl = re.search(r'file="([^"]*)"', attrs)
        if t and fl:
            out.append((float(t.group(1)), html.unescape(fl.group(1))))
    return out


def run_frames(base_dir, run, t_end):
    """[(time s, positions)] of a run: its series, else its final surface, else []."""
    if run.get("surface_series"):
        pvd = os.path.join(base_dir, run["surface_series"])
        folder = os.path.dirname(pvd)
        frames = [(t, read_vtp_points(os.path.join(folder, name))) for t, name in read_pvd(pvd)]
        if frames:
            return frames
    if run.get("final_surface"):
        v, _ = read_obj(os.path.join(base_dir, run["final_surface"]))
        return [(t_end, v)]
    return []


def b64(data):
    return base64.b64encode(data).decode("ascii")


def encode_series(frames, base):
    """frames: (F, n, 3) float positions; base: (n, 3). -> (scale[3], base64 text)."""
    off = frames - base[None, :, :]
    scale = np.abs(off).max(axis=(0, 1)) / 32767.0 if off.size else np.zeros(3)
    scale = np.where(scale > 0, scale, 1e-12)
    q = np.rint(off / scale).astype(np.int32)
    q = np.clip(q, -32767, 32767).astype(np.int16)
    d = q.astype(np.int32)
    d[1:] -= q[:-1].astype(np.int32)
    d = d.astype(np.int16)  # wraps like the decoder's Int16Array
    planes = np.ascontiguousarray(d.transpose(0, 2, 1)).view(np.uint8).reshape(-1, 2)
    packed = np.concatenate([planes[:, 0], planes[:, 1]]).tobytes()
    return [float(s) for s in scale], b64(zlib.compress(packed, 6))


def num(v):
    return v if isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) else None


def load_folder(results_path):
    """Reads a results folder into plain arrays: (doc, rest V or None, faces, runs) where each
    run is (record, [(time, positions)])."""
    base_dir = os.path.dirname(results_path)
    with open(results_path) as f:
        doc = json.load(f)
    scene = doc.get("scene") or {}
    t_end = None
    if num(scene.get("dt")) and scene.get("steps") is not None:
        t_end = scene["dt"] * scene["steps"]
    rest, faces = None, None
    rest_file = (doc.get("organ") or {}).get("rest_surface")
    if rest_file and os.path.exists(os.path.join(base_dir, rest_file)):
        rest, faces = read_obj(os.path.join(base_dir, rest_file))
    runs = []
    for r in doc.get("runs", []):
        end = t_end
        if num(scene.get("dt")) and r.get("steps") is not None:
            end = scene["dt"] * r["steps"]
        frames = run_frames(base_dir, r, end if end is not None else 0.0)
        runs.append((r, frames))
    if faces is None:
        for r, frames in runs:
            if r.get("final_surface") and frames:
                _, faces = read_obj(os.path.join(base_dir, r["final_surface"]))
                break
    return doc, rest, faces, runs


def build(doc, rest, faces, runs, budget=BUDGET_BYTES, link_base=""):
    """The viewer's data (a JSON-able dict) from load_folder's output (or synthetic arrays).
    None when no run has a surface."""
    absent = [{"label": r.get("label", "?"), "status": r.get("status"),
               "message": (r.get("message") or "")[:200]} for r, fr in runs if not fr]
    runs = [(r, fr) for r, fr in runs if fr]
    if not runs or faces is None:
        return None
    n = min(len(fr[0][1]) for _, fr in runs)
    if rest is not None:
        n = min(n, len(rest))
    faces = faces[(faces < n).all(axis=1)]
    key = lambda t: round(t, 9)
    times = sorted({key(t) for _, fr in runs for t, _ in fr})
    ref_i = next((i for i, (r, _) in enumerate(runs) if r.get("role") == "reference"), None)

    # Error statistics at full precision (the viewer colours the quantised positions).
    ref_at = {}
    if ref_i is not None:
        ref_at = {key(t): x[:n] for t, x in runs[ref_i][1]}
    stats = []
    true_max, ok_max, where = 0.0, 0.0, None
    for i, (r, fr) in enumerate(runs):
        per = {}
        if i != ref_i:
            for t, x in fr:
                ref = ref_at.get(key(t))
                if ref is None:
                    continue
                e = np.linalg.norm(x[:n] - ref, axis=1)
                e = e[np.isfinite(e)]
                if not e.size:
                    continue
                m = float(e.max())
                per[key(t)] = m
                if m > true_max:
                    true_max, where = m, (r.get("label"), t)
                if r.get("status") == "ok" and r.get("valid", True) is not False:
                    ok_max = max(ok_max, m)
        stats.append(per)
    colour_max = ok_max if ok_max > 0 else true_max

    thin = 1
    while True:
        keep = list(range(0, len(times), thin))
        if keep[-1] != len(times) - 1:
            keep.append(len(times) - 1)
        shown = [times[k] for k in keep]
        out_runs, total = [], 0
        for i, (r, fr) in enumerate(runs):
            mine = {key(t): x for t, x in fr}
            local_t = [t for t in shown if t in mine]
            if not local_t:  # only frames that thinning dropped: keep its last one
                local_t = [key(fr[-1][0])]
            arr = np.stack([mine[t][:n] for t in local_t])
            arr = np.where(np.isfinite(arr), arr, 0.0)
            base = rest[:n] if rest is not None else arr[0]
            scale, data = encode_series(arr, base)
            total += len(data)
            out_runs.append(_run_entry(r, local_t, scale, data, stats[i],
                                       None if rest is not None else base, link_base))
        if total <= budget or thin >= len(times):
            break
        thin *= 2

    # The parameters that tell runs of the same model apart (shown first, in bold).
    by_model = {}
    for entry in out_runs:
        by_model.setdefault(entry["model"], []).append(entry)
    for group in by_model.values():
        keys = set().union(*(e["params"].keys() for e in group))
        for e in group:
            e["distinct"] = sorted(k for k in keys if len({json.dumps(g["params"].get(k))
                                                           for g in group}) > 1)
    v = {
        "format": "deformbench-viewer/1",
        "scene": (doc.get("scene") or {}).get("name", ""),
        "n": int(n),
        "faces": b64(zlib.compress(np.ascontiguousarray(faces, dtype="<u4").tobytes(), 6)),
        "nfaces": int(len(faces)),
        "rest": None if rest is None else _f32(rest[:n]),
        "times": shown,
        "frames_written": len(times),
        "thinned": thin if thin > 1 else None,
        "reference": ref_i,
        "colour": {"max_m": colour_max, "true_max_m": true_max,
                   "true_max_at": list(where) if where else None},
        "runs": out_runs,
        "absent": absent,
        "interaction": _interaction(doc, rest[:n] if rest is not None else None),
        "encoded_bytes": total,
    }
    return v


def _f32(a):
    return b64(zlib.compress(np.ascontiguousarray(a, dtype="<f4").tobytes(), 6))


def _run_entry(r, local_t, scale, data, per, base, link_base):
    e = r.get("error") or {}
    sm = r.get("step_ms") or {}
    return {
        "label": r.get("label", r.get("model", "?")),
        "model": r.get("model"),
        "role": r.get("role", "model"),
        "params": r.get("params") or {},
        "status": r.get("status"),
        "message": r.get("message", ""),
        # A failed or unsupported run is never valid, whatever an old results.json says.
        "valid": r.get("valid") if r.get("status", "ok") == "ok" else False,
        "invalid_reason": r.get("invalid_reason") or (
            None if r.get("status", "ok") == "ok" else r.get("status")),
        "reference_valid": r.get("reference_valid"),
        "reference_invalid_reason": r.get("reference_invalid_reason"),
        "step_ms": num(sm.get("median")),
        "precompute_s": num(r.get("precompute_s")),
        "rmse_all_m": num(e.get("rmse_all")),
        "max_m": num(e.get("max")),
        "grasp_residual_m": num(r.get("grasp_residual_m")),
        "settled_at_s": num(r.get("settled_at_s")),
        "times": local_t,
        "scale": scale,
        "base": None if base is None else _f32(base),
        "data": data,
        "frame_max_m": [per.get(t) for t in local_t],
    }


def _interaction(doc, rest):
    it = doc.get("interaction") or {}
    out = {"tools": it.get("tools") or [], "loads": it.get("loads") or [], "boxes": [],
           "fixed_vertices": [], "grasped_vertices": []}
    fixed = it.get("fixed") or {}
    if rest is not None:
        lo, hi = rest.min(axis=0), rest.max(axis=0)
        pad = 0.02 * float((hi - lo).max())
        mask = np.zeros(len(rest), dtype=bool)
        for b in fixed.get("boxes") or []:
            blo, bhi = np.array(b[0], dtype=float), np.array(b[1], dtype=float)
            mask |= ((rest >= blo) & (rest <= bhi)).all(axis=1)
            # Drawn clipped to the organ's bounds (scene boxes are often "everything below z").
            out["boxes"].append([list(np.maximum(blo, lo - pad)), list(np.minimum(bhi, hi + pad))])
        for i in fixed.get("surface_vertices") or []:
            if 0 <= i < len(rest):
                mask[i] = True
        out["fixed_vertices"] = [int(i) for i in np.nonzero(mask)[0]]
        grasped = set()
        for t in out["tools"]:
            if t.get("type") != "grasper":
                continue
            prev = "open"
            for k in t.get("trajectory") or []:
                if k.get("jaw") == "closed" and prev != "closed":
                    p = np.array(k["pos"], dtype=float)
                    d = np.linalg.norm(rest - p, axis=1)
                    sel = np.nonzero(d <= t.get("radius", 0))[0]
                    grasped.update(int(i) for i in (sel if sel.size else [int(d.argmin())]))
                prev = k.get("jaw", prev)
        out["grasped_vertices"] = sorted(grasped)
    return out


def library_text():
    """three.js and its orbit controls in one script (what lib_src points to)."""
    three, orbit = viewer_assets()
    return three + "\n;\n" + orbit


def page_parts(data, lib_src=None):
    """(head, body) HTML of the viewer with its data; three.js inlined, or loaded from lib_src
    (a relative URL of library_text() written once beside many viewers). Raises OSError when
    three.js is missing."""
    with open(os.path.join(VIEWER_DIR, "viewer.js")) as f:
        app = f.read()
    with open(os.path.join(VIEWER_DIR, "viewer.css")) as f:
        css = f.read()
    # Inside <script> only "</script" and "<!--" change how HTML reads the text: escape every
    # "<" (and ">", "&") as \u003c etc., which JSON.parse reads back unchanged.
    payload = (json.dumps(data, separators=(",", ":")).replace("<", "\\u003c")
               .replace(">", "\\u003e").replace("&", "\\u0026"))
    head = "<style>%s</style>" % css
    lib = ('<script src="%s"></script>' % html.escape(lib_src) if lib_src else
           "<script>%s</script>" % library_text())
    body = ('<div id="dbv" class="dbv"></div>'
            '<script type="application/json" id="dbv-data">%s</script>'
            "%s<script>%s</script>" % (payload, lib, app))
    return head, body


def standalone(data, title, lib_src=None):
    head, body = page_parts(data, lib_src)
    return ('<!DOCTYPE html><html><head><meta charset="utf-8"><title>%s</title>%s'
            '<style>body{font-family:sans-serif;margin:0.8em;color:#222}</style></head>'
            "<body><h2>%s</h2>%s</body></html>" % (html.escape(title), head, html.escape(title),
                                                   body))
