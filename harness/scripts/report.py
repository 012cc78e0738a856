#!/usr/bin/env python3
"""A self-contained HTML report of a deformbench folder (results, tables, sweep or stability).

usage: report.py DIR OUT.html

Sections (each present when the folder has its data):
  tables          every <table>.json (format deformbench-table/1), and results.json run tables
  calibration     calibration.json of `deformbench calibrate` (here or one per subfolder):
                  the metric at the defaults and calibrated, training and validation
  sweep           error against run time (sweep.json; the plot is drawn again with matplotlib)
  stability       the stability table summary and one stability map per model
  viewer          the folder's own results.json: an interactive 3D viewer (three.js, inlined) of
                  every run side by side with the reference, over the surface series, coloured
                  by the distance to the reference (viewer_data.py)
  organs          the final deformed organ of each model side by side, coloured by the distance
                  to the reference's final surface (matplotlib 3D render of final.obj)
Every results.json in a subfolder (the runs of tables, sweep, stability) gets a viewer.html of its
own beside it, and the rows of those reports link to it. The error-against-run-time plots are
SVG: hovering a point names the run, clicking it opens the run's viewer.
Images are PNG embedded as base64, so the file opens anywhere. Without matplotlib the report is
written without pictures and says so; without three.js (libjs-three) without viewers.
"""
import base64
import glob
import html
import io
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from deform_plot_common import model_colour, nearest_label  # noqa: E402

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    HAVE_MPL = True
except ImportError:
    HAVE_MPL = False

MAX_ORGAN_FIGURES = 12
MAX_VIEWERS = 400
VIEWER_LIB = "viewer-three.js"  # three.js + OrbitControls, shared by the runs' viewer.html


def esc(x):
    return html.escape(str(x))


# ------------------------------------------------------------------------- what the report reads
# Every file is checked before it is drawn: a field of the wrong type, a number no measurement
# can have (|v| > 1e100, where the report's arithmetic would overflow) or a surface that is not
# the one its results.json describes ends the report with one line naming the file and the
# field, exit code 2 (docs/commands.md, "report").

PLAUSIBLE = 1e100


class BadInput(Exception):
    pass


def load_json(path):
    try:
        with open(path) as f:
            return json.load(f)
    except OSError as e:
        raise BadInput("%s: cannot read: %s" % (path, e.strerror or e))
    except ValueError as e:
        raise BadInput("%s: not JSON: %s" % (path, e))


def need(cond, path, where, problem):
    if not cond:
        raise BadInput("%s: %s: %s" % (path, where, problem))


def check_number(path, where, v, nullable=True, minimum=None):
    if v is None and nullable:
        return
    need(isinstance(v, (int, float)) and not isinstance(v, bool), path, where,
         "expected a number, got %s" % type_name(v))
    need(math.isfinite(v) and abs(v) <= PLAUSIBLE, path, where,
         "%r is not a plausible value (over %g)" % (v, PLAUSIBLE))
    if minimum is not None:
        need(v >= minimum, path, where, "%r is below %g" % (v, minimum))


def check_string(path, where, v, nullable=False):
    if v is None and nullable:
        return
    need(isinstance(v, str), path, where, "expected a string, got %s" % type_name(v))


def type_name(v):
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, (int, float)):
        return "a number (%r)" % v
    if isinstance(v, str):
        return "a string (%r)" % (v if len(v) < 40 else v[:37] + "...")
    return "a list" if isinstance(v, list) else "an object"


def check_object(path, where, v, nullable=False):
    if v is None and nullable:
        return {}
    need(isinstance(v, dict), path, where, "expected an object, got %s" % type_name(v))
    return v


def count_obj_vertices(data):
    return sum(1 for line in data.splitlines() if line.startswith(b"v "))


def check_results(path):
    """A results.json and the final surfaces it names; returns the document."""
    import hashlib
    doc = check_object(path, "top level", load_json(path))
    need(doc.get("format") == "deformbench-results/1", path, "format",
         "expected \"deformbench-results/1\", got %s" % type_name(doc.get("format")))
    scene = check_object(path, "scene", doc.get("scene"))
    check_string(path, "scene.name", scene.get("name"))
    organ = check_object(path, "organ", doc.get("organ"), nullable=True)
    check_number(path, "organ.vertices", organ.get("vertices"), minimum=0)
    runs = doc.get("runs")
    need(isinstance(runs, list), path, "runs", "expected a list, got %s" % type_name(runs))
    base = os.path.dirname(path)
    for i, r in enumerate(runs):
        at = "runs[%d]" % i
        check_object(path, at, r)
        check_string(path, at + ".label", r.get("label"))
        at = "runs[%d] (%s)" % (i, r["label"])
        for k in ("status", "model", "role", "message", "invalid_reason"):
            check_string(path, at + "." + k, r.get(k), nullable=k != "status")
        need(r["status"] in ("ok", "diverged", "unsupported", "failed"), path, at + ".status",
             "unknown status %r" % r["status"])
        need(r.get("valid") in (None, True, False), path, at + ".valid",
             "expected true or false, got %s" % type_name(r.get("valid")))
        check_object(path, at + ".params", r.get("params"), nullable=True)
        check_number(path, at + ".precompute_s", r.get("precompute_s"), minimum=0)
        for k, v in check_object(path, at + ".step_ms", r.get("step_ms"), nullable=True).items():
            check_number(path, at + ".step_ms." + k, v, minimum=0)
        for k, v in check_object(path, at + ".error", r.get("error"), nullable=True).items():
            if k.startswith("rmse_") and k not in ("rmse_k_samples", "rmse_k_excluded_grasped") \
                    or k in ("max", "loss_ratio") or k.startswith("reference_displacement_"):
                check_number(path, at + ".error." + k, v, minimum=0)
        surface = r.get("final_surface")
        if surface is None:
            continue
        check_string(path, at + ".final_surface", surface)
        rel = os.path.normpath(surface)
        need(not os.path.isabs(rel) and not rel.startswith(".."), path, at + ".final_surface",
             "%r is outside the results folder" % surface)
        try:
            with open(os.path.join(base, rel), "rb") as f:
                data = f.read()
        except OSError as e:
            raise BadInput("%s: %s.final_surface: cannot read %s: %s"
                           % (path, at, surface, e.strerror or e))
        n = count_obj_vertices(data)
        want = r.get("final_surface_vertices")
        if want is not None:
            check_number(path, at + ".final_surface_vertices", want, minimum=0)
            need(n == want, path, at + ".final_surface",
                 "%s has %d vertices, results.json says %d (the surfaces are from another run)"
                 % (surface, n, want))
        elif organ.get("vertices") is not None:
            need(n >= organ["vertices"], path, at + ".final_surface",
                 "%s has %d vertices, the organ %d (the surfaces are from another run)"
                 % (surface, n, organ["vertices"]))
        digest = r.get("final_surface_sha256")
        if digest is not None:
            check_string(path, at + ".final_surface_sha256", digest)
            need(hashlib.sha256(data).hexdigest() == digest, path, at + ".final_surface",
                 "%s does not match its SHA-256 in results.json (the surfaces are from "
                 "another run)" % surface)
    return doc


def check_table(path, doc):
    for k in ("table", "title"):
        check_string(path, k, doc.get(k))
    cols = doc.get("columns")
    need(isinstance(cols, list), path, "columns", "expected a list, got %s" % type_name(cols))
    for i, c in enumerate(cols):
        check_object(path, "columns[%d]" % i, c)
        check_string(path, "columns[%d].key" % i, c.get("key"))
        check_string(path, "columns[%d].header" % i, c.get("header"))
    rows = doc.get("rows")
    need(isinstance(rows, list), path, "rows", "expected a list, got %s" % type_name(rows))
    for i, r in enumerate(rows):
        check_object(path, "rows[%d]" % i, r)
        for k, v in r.items():
            if isinstance(v, float):
                check_number(path, "rows[%d].%s" % (i, k), v)


def check_sweep(path):
    doc = check_object(path, "top level", load_json(path))
    pts = doc.get("points")
    need(isinstance(pts, list), path, "points", "expected a list, got %s" % type_name(pts))
    for i, p in enumerate(pts):
        check_object(path, "points[%d]" % i, p)
        for k in ("label", "model", "status"):
            check_string(path, "points[%d].%s" % (i, k), p.get(k))
        for k in ("ms_median", "rmse_50", "rmse_all", "max"):
            check_number(path, "points[%d].%s" % (i, k), p.get(k), minimum=0)
    check_number(path, "haptic_budget_ms", doc.get("haptic_budget_ms"), minimum=0)
    if doc.get("reference_check") is not None:
        check_object(path, "reference_check", doc["reference_check"])
        check_string(path, "reference_check.summary", doc["reference_check"].get("summary"))
    return doc


def check_stability(path):
    doc = check_object(path, "top level", load_json(path))
    check_table(path, doc)
    for i, r in enumerate(doc["rows"]):
        check_string(path, "rows[%d].model" % i, r.get("model"))
        check_string(path, "rows[%d].status" % i, r.get("status"))
    return doc


def check_calibration(path, c):
    check_string(path, "metric", c.get("metric"), nullable=True)
    for k, v in check_object(path, "params", c.get("params"), nullable=True).items():
        check_number(path, "params." + k, v, nullable=False)
    for k, v in check_object(path, "defaults", c.get("defaults"), nullable=True).items():
        check_number(path, "defaults." + k, v)
    for part in ("train", "validation"):
        o = check_object(path, part, c.get(part))
        for k in ("before", "after"):
            check_number(path, "%s.%s" % (part, k), o.get(k))
    check_number(path, "evaluations", c.get("evaluations"))
    check_number(path, "wall_s", c.get("wall_s"))


def cell(v):
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if v != 0 and (abs(v) >= 1e6 or abs(v) < 1e-3):
            return "%.3e" % v
        return "%.4g" % v
    return str(v)


def html_table(columns, rows, links=None):
    """links: per row, the href of its run's viewer (or None): a "viewer" column when any."""
    links = links if links and any(links) else None
    out = ["<table><thead><tr>"]
    out += ["<th>%s</th>" % esc(h) for _, h in columns]
    if links:
        out.append("<th>viewer</th>")
    out.append("</tr></thead><tbody>")
    for i, r in enumerate(rows):
        out.append("<tr>")
        for key, _ in columns:
            v = r.get(key)
            cls = ""
            if key == "status" and isinstance(v, str):
                cls = ' class="st-%s"' % esc(v.split(" ")[0].split(":")[0])
            text = cell(v)
            if len(text) > 160:
                text = text[:157] + "..."
            out.append("<td%s>%s</td>" % (cls, esc(text)))
        if links:
            out.append('<td>%s</td>' % ('<a href="%s">view</a>' % esc(links[i]) if links[i] else ""))
        out.append("</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def png_tag(fig_or_path, alt):
    if isinstance(fig_or_path, str):
        with open(fig_or_path, "rb") as f:
            data = f.read()
    else:
        buf = io.BytesIO()
        fig_or_path.savefig(buf, format="png", dpi=100)
        plt.close(fig_or_path)
        data = buf.getvalue()
    return '<img alt="%s" src="data:image/png;base64,%s">' % (
        esc(alt), base64.b64encode(data).decode("ascii"))


def read_obj(path):
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                verts.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) for t in line.split()[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                for k in range(1, len(idx) - 1):
                    faces.append((idx[0], idx[k], idx[k + 1]))
    return verts, faces


def organ_figure(results_path):
    """One figure: each ok model's final surface, coloured by distance to the reference's."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    import numpy as np

    base = os.path.dirname(results_path)
    doc = check_results(results_path)
    runs = [r for r in doc["runs"] if r.get("final_surface")]
    ref = next((r for r in runs if r.get("role") == "reference"), None)
    models = [r for r in runs if r.get("role") != "reference"]
    if not models:
        return None, ""
    ref_v = None
    if ref:
        ref_v, _ = read_obj(os.path.join(base, ref["final_surface"]))
        ref_v = np.array(ref_v)
    panels = models + ([ref] if ref is not None else [])
    surfaces = []
    ok_max, true_max, true_at = 0.0, 0.0, ""
    for r in panels:
        v, fcs = read_obj(os.path.join(base, r["final_surface"]))
        v = np.array(v)
        fcs = np.array(fcs)
        err = None
        if ref_v is not None and r is not ref:
            n = min(len(v), len(ref_v))
            err = np.zeros(len(v))
            err[:n] = np.linalg.norm(v[:n] - ref_v[:n], axis=1) * 1e3
            m = float(err[:n].max()) if n else 0.0
            if m > true_max:
                true_max, true_at = m, r["label"]
            if run_valid(r):
                ok_max = max(ok_max, m)
        surfaces.append((r, v, fcs, err))
    # The full range of the valid runs; a run beyond it (invalid, diverged) is drawn in the
    # over colour, which the bar shows and names.
    vmax = ok_max if ok_max > 0 else (true_max if true_max > 0 else 1.0)
    clipped = true_max > vmax * (1 + 1e-9)
    cols = len(surfaces)
    fig = plt.figure(figsize=(3.4 * cols + 1.2, 3.8))
    cmap = plt.get_cmap("viridis").copy()
    cmap.set_over("magenta")
    lo = np.min([s[1].min(axis=0) for s in surfaces], axis=0)
    hi = np.max([s[1].max(axis=0) for s in surfaces], axis=0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    norm = plt.Normalize(0, vmax)
    for i, (r, v, fcs, err) in enumerate(surfaces):
        ax = fig.add_subplot(1, cols, i + 1, projection="3d")
        tris = v[fcs]
        if err is not None:
            # The face colour is that of its largest vertex distance, so nothing is averaged
            # away and every colour is on the bar.
            colours = cmap(norm(err[fcs].max(axis=1)))
        else:
            colours = [(0.86, 0.74, 0.64, 1.0)] * len(fcs)
        coll = Poly3DCollection(tris, facecolors=colours, edgecolors="none", linewidths=0)
        ax.add_collection3d(coll)
        for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
            setter(c - half, c + half)
        ax.view_init(elev=25, azim=-60)
        ax.set_axis_off()
        title = r["label"] + (" [reference]" if r is ref else "")
        # The parameters that differ between this folder's runs of the same model: two runs
        # with different parameters never carry the same title.
        same = [q for q in panels if q.get("model") == r.get("model")]
        pr = r.get("params") or {}
        differ = sorted(k for k in pr if len({json.dumps((q.get("params") or {}).get(k))
                                                 for q in same}) > 1)
        if differ:
            params = ", ".join("%s=%s" % (k, pr[k]) for k in differ)
            title += "\n" + (params if len(params) < 48 else params[:45] + "...")
        if r.get("error") and r["error"].get("rmse_all") is not None:
            title += "\nrmse_all %.3g mm" % (1e3 * r["error"]["rmse_all"])
        if not run_valid(r):
            title += "\nINVALID: %s" % r.get("invalid_reason", r.get("status", ""))
        if r.get("reference_valid") is False:
            title += "\nagainst an invalid reference"
        ax.set_title(title, fontsize=8)
    if ref_v is not None:
        sm = plt.cm.ScalarMappable(cmap=cmap, norm=norm)
        label = "distance to reference (mm), 0 to %.3g" % vmax
        if clipped:
            label += "\nclipped: magenta beyond; true max %.3g mm (%s)" % (true_max, true_at)
        fig.colorbar(sm, ax=fig.axes, shrink=0.7, label=label, extend="max" if clipped else "neither")
    caption = "%s: final surfaces%s" % (
        doc["scene"]["name"],
        ", coloured by distance to the reference (%s), range 0 to %.3g mm%s" % (
            ref["label"], vmax, "; clipped, true maximum %.3g mm (%s)" % (true_max, true_at)
            if clipped else " (the largest distance)") if ref else
        " (no reference: uniform colour)")
    return fig, caption


def run_hash(label):
    """The URL hash that makes a viewer show one run (and the reference)."""
    from urllib.parse import quote
    return "#run=" + quote(label, safe="()=,.")


def run_valid(r):
    """A run may be ranked: it ended ok and is not marked invalid (a failed or unsupported run
    is never valid, whatever an old results.json says)."""
    return r.get("status", "ok") == "ok" and r.get("valid", True) is not False


def reference_mark(r):
    """'against an invalid reference (why)' for a run whose errors are against one, else ''."""
    if r.get("reference_valid") is False:
        why = r.get("reference_invalid_reason") or ""
        return "against an invalid reference" + (" (%s)" % why if why else "")
    return ""


def run_point_text(r, ms, err, err_name):
    params = ", ".join("%s=%s" % kv for kv in sorted((r.get("params") or {}).items()))
    ref = reference_mark(r)
    return "%s (%s)\n%s\n%s %.4g mm, %.4g ms/step%s%s" % (
        r.get("label", "?"), r.get("model", ""), params or "default parameters", err_name,
        1e3 * err, ms, "" if run_valid(r) else
        "\nINVALID: %s" % r.get("invalid_reason", r.get("status", "")),
        "\n" + ref if ref else "")


def svg_scatter(points, xlabel, ylabel, budget_ms=None):
    """An error-against-time plot as inline SVG, log axes where the data span a decade.
    points: dicts x, y (> 0), series, text (the hover text), href (or None), ring (bool), and
    optionally model and plugin (the colour: one per model, deform_plot_common.model_colour),
    calibrated (a diamond; its series' front dashed) and front (on its series' Pareto front:
    joined by a line in the series' colour)."""
    pts = [p for p in points if p["x"] and p["y"] and p["x"] > 0 and p["y"] > 0]
    if not pts:
        return ""
    W, H, L, R, T, B = 720, 380, 70, 170, 15, 45
    series = []
    for p in pts:
        if p["series"] not in series:
            series.append(p["series"])
    first = {}
    for p in pts:
        first.setdefault(p["series"], p)

    def colour(p):
        return model_colour(p.get("model", p["series"]), p.get("plugin"))

    def axis(vals, extra=()):
        lo, hi = min(list(vals) + list(extra)), max(list(vals) + list(extra))
        log = hi / lo > 10
        if log:
            a, b = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
            f = lambda v: (math.log10(v) - a) / max(b - a, 1e-9)
            ticks = [10.0 ** k for k in range(a, b + 1)]
        else:
            pad = (hi - lo) * 0.1 or hi * 0.1
            a, b = max(lo - pad, 0), hi + pad
            f = lambda v: (v - a) / (b - a)
            ticks = [a + (b - a) * k / 4 for k in range(5)]
        return f, ticks, log

    fx, xt, xlog = axis([p["x"] for p in pts], [budget_ms] if budget_ms else [])
    fy, yt, ylog = axis([p["y"] for p in pts])
    X = lambda v: L + fx(v) * (W - L - R)
    Y = lambda v: H - B - fy(v) * (H - T - B)
    o = ['<svg class="scatter" xmlns="http://www.w3.org/2000/svg" width="%d" height="%d" '
         'font-size="11" font-family="sans-serif">' % (W, H),
         '<rect x="%d" y="%d" width="%d" height="%d" fill="none" stroke="#888"/>'
         % (L, T, W - L - R, H - T - B)]
    for v in xt:
        o.append('<line x1="%.1f" x2="%.1f" y1="%d" y2="%d" stroke="#eee"/>'
                 '<text x="%.1f" y="%d" text-anchor="middle">%s</text>'
                 % (X(v), X(v), T, H - B, X(v), H - B + 14, "%.3g" % v))
    for v in yt:
        o.append('<line x1="%d" x2="%d" y1="%.1f" y2="%.1f" stroke="#eee"/>'
                 '<text x="%d" y="%.1f" text-anchor="end">%s</text>'
                 % (L, W - R, Y(v), Y(v), L - 4, Y(v) + 4, "%.3g" % v))
    o.append('<text x="%d" y="%d" text-anchor="middle">%s%s</text>'
             % ((L + W - R) // 2, H - 8, esc(xlabel), " (log)" if xlog else ""))
    o.append('<text transform="translate(14,%d) rotate(-90)" text-anchor="middle">%s%s</text>'
             % ((T + H - B) // 2, esc(ylabel), " (log)" if ylog else ""))
    if budget_ms:
        o.append('<line x1="%.1f" x2="%.1f" y1="%d" y2="%d" stroke="red" stroke-dasharray="3,3"/>'
                 % (X(budget_ms), X(budget_ms), T, H - B))
    for name in series:  # each series' own front, a line through its points by time
        front = sorted([p for p in pts if p["series"] == name and p.get("front")],
                       key=lambda p: p["x"])
        if len(front) > 1:
            o.append('<polyline fill="none" stroke="%s" stroke-width="1.5"%s points="%s"/>'
                     % (colour(front[0]), ' stroke-dasharray="5,3"'
                        if front[0].get("calibrated") else "",
                        " ".join("%.1f,%.1f" % (X(p["x"]), Y(p["y"])) for p in front)))

    def marker(p, x, y, fill, stroke, width, extra=""):
        if p.get("calibrated"):  # a diamond
            return ('<path d="M%.1f %.1fl6 6l-6 6l-6 -6z" fill="%s" stroke="%s" '
                    'stroke-width="%d"%s>' % (x, y - 6, fill, stroke, width, extra))
        return ('<circle cx="%.1f" cy="%.1f" r="5" fill="%s" stroke="%s" stroke-width="%d"%s>'
                % (x, y, fill, stroke, width, extra))

    for p in pts:
        c = colour(p)
        hollow = not p.get("valid", True) or p.get("calibrated")
        dot = marker(p, X(p["x"]), Y(p["y"]), "white" if hollow else c,
                     "black" if p.get("ring") else c, 2 if p.get("ring") else 1,
                     ' style="cursor:pointer"' if p.get("href") else "")
        dot += "<title>%s</title>%s" % (esc(p["text"]),
                                        "</path>" if p.get("calibrated") else "</circle>")
        o.append('<a href="%s">%s</a>' % (esc(p["href"]), dot) if p.get("href") else dot)
    for i, name in enumerate(series):
        p = first[name]
        o.append(marker(p, W - R + 12, T + 12 + 16 * i, "white" if p.get("calibrated")
                        else colour(p), colour(p), 1) +
                 ("</path>" if p.get("calibrated") else "</circle>") +
                 '<text x="%d" y="%d">%s</text>' % (W - R + 22, T + 16 + 16 * i, esc(name[:22])))
    o.append("</svg>")
    return "".join(o)


def results_table(path, viewer_href=None):
    doc = check_results(path)
    rows, links = [], []

    def href_of(r):
        # The folder's own viewer is on this page (an anchor); another page filters by run.
        if not viewer_href:
            return None
        return viewer_href if viewer_href.startswith("#") else viewer_href + run_hash(r["label"])

    for r in doc["runs"]:
        links.append(href_of(r))
        e = r.get("error") or {}
        sm = r.get("step_ms") or {}
        rows.append({
            "label": r["label"] + (" [ref]" if r.get("role") == "reference" else ""),
            "status": r["status"],
            "ms": sm.get("median"),
            "p95": sm.get("p95"),
            "precompute_s": r.get("precompute_s"),
            "rmse_10": 1e3 * e["rmse_10"] if e.get("rmse_10") is not None else None,
            "rmse_50": 1e3 * e["rmse_50"] if e.get("rmse_50") is not None else None,
            "rmse_all": 1e3 * e["rmse_all"] if e.get("rmse_all") is not None else None,
            "loss_ratio": e.get("loss_ratio"),
            "valid": r.get("valid") if r.get("status", "ok") == "ok" else False,
            "invalid_reason": r.get("invalid_reason") or (
                None if run_valid(r) else r.get("status")),
            "reference": reference_mark(r) or None,
            "message": r.get("message", ""),
        })
    cols = [("label", "run"), ("status", "status"), ("ms", "ms/step"), ("p95", "p95 ms"),
            ("precompute_s", "precompute s"), ("rmse_10", "rmse_10 mm"),
            ("rmse_50", "rmse_50 mm"), ("rmse_all", "rmse_all mm"), ("loss_ratio", "loss ratio")]
    if any(r["valid"] is not None for r in rows):
        cols += [("valid", "valid"), ("invalid_reason", "why invalid")]
    if any(r["reference"] for r in rows):
        cols.append(("reference", "errors"))
    cols.append(("message", "message"))
    pts = []
    for r in doc["runs"]:
        e, sm = r.get("error") or {}, r.get("step_ms") or {}
        if r.get("role") == "reference" or e.get("rmse_all") is None or not sm.get("median"):
            continue
        calibrated = bool(r.get("calibration")) or r.get("label", "").endswith("+cal")
        pts.append({"x": sm["median"], "y": 1e3 * e["rmse_all"],
                    "series": r.get("model", "?") + (" calibrated" if calibrated else ""),
                    "model": r.get("model", "?"), "plugin": r.get("plugin"),
                    "calibrated": calibrated,
                    "text": run_point_text(r, sm["median"], e["rmse_all"], "rmse_all"),
                    "href": href_of(r),
                    "valid": run_valid(r) and r.get("reference_valid") is not False})
    plot = svg_scatter(pts, "ms per step (median)", "rmse_all (mm)") if len(pts) > 1 else ""
    return doc, html_table(cols, rows, links) + plot


def main():
    try:
        return run_report()
    except BadInput as e:  # `deformbench report` prefixes "deformbench: report: "
        print(e)
        return 2
    except Exception as e:  # one line, never a traceback
        print("internal error: %s: %s" % (type(e).__name__, e))
        return 3


def run_report():
    if len(sys.argv) != 3:
        print(__doc__)
        return 2
    root, out = sys.argv[1], sys.argv[2]
    if not os.path.isdir(root):
        print("%s: not a folder" % root)
        return 2
    sections = []
    notes = []
    # Every file the report reads is checked first: a bad one ends it with one line.
    for path in sorted(glob.glob(os.path.join(root, "**", "results.json"), recursive=True)):
        check_results(path)
    if os.path.exists(os.path.join(root, "sweep.json")):
        check_sweep(os.path.join(root, "sweep.json"))
    if os.path.exists(os.path.join(root, "stability.json")):
        check_stability(os.path.join(root, "stability.json"))
    if not HAVE_MPL:
        notes.append("matplotlib is not installed for %s: the report has no pictures."
                     % sys.executable)

    # Viewers: the folder's own results inline, every results.json below in a viewer.html beside it.
    viewer_head, viewer_section, viewers, viewer_bytes = "", None, {}, 0
    written_lib = set()
    try:
        import viewer_data
        viewer_data.viewer_assets()
    except (ImportError, OSError) as e:
        viewer_data = None
        notes.append("no 3D viewer: %s" % e)
    if viewer_data is not None:
        found = sorted(glob.glob(os.path.join(root, "**", "results.json"), recursive=True))
        if len(found) > MAX_VIEWERS:
            notes.append("viewers written for the first %d of %d results folders"
                         % (MAX_VIEWERS, len(found)))
        for path in found[:MAX_VIEWERS]:
            rel = os.path.relpath(os.path.dirname(path), root)
            try:
                doc_, rest, faces, runs = viewer_data.load_folder(path)
                data = viewer_data.build(doc_, rest, faces, runs)
                if data is None:
                    continue
                if rel == ".":
                    viewer_head, body_ = viewer_data.page_parts(data)
                    viewer_section = body_
                    viewers["."] = "#viewer"
                    continue
                # The runs' viewers share one copy of three.js at the top of the folder.
                lib = os.path.join(root, VIEWER_LIB)
                if not os.path.exists(lib) or lib not in written_lib:
                    with open(lib + ".tmp", "w") as f:
                        f.write(viewer_data.library_text())
                    os.replace(lib + ".tmp", lib)
                    written_lib.add(lib)
                    viewer_bytes += os.path.getsize(lib)
                target = os.path.join(os.path.dirname(path), "viewer.html")
                page = viewer_data.standalone(
                    data, "deformbench viewer: %s (%s)" % (data["scene"], rel),
                    os.path.relpath(lib, os.path.dirname(target)))
                with open(target + ".tmp", "w") as f:
                    f.write(page)
                os.replace(target + ".tmp", target)
                viewer_bytes += os.path.getsize(target)
                viewers[rel] = os.path.relpath(target, os.path.dirname(os.path.abspath(out)))
            except Exception as e:  # a broken results folder must not stop the report
                notes.append("%s: no viewer (%s: %s)" % (rel, type(e).__name__, e))
    if viewer_section:
        sections.append(("viewer", "Viewer", viewer_section))

    def viewer_of(folder):
        return viewers.get(os.path.normpath(folder)) if folder else None

    # Tables (deformbench-table/1) at the top level.
    table_html = []
    order = ["metaballs-construction", "method-comparison", "bem-timing", "bem-accuracy",
             "hybrid-accuracy", "hybrid-timing"]

    def table_rank(path):
        name = os.path.splitext(os.path.basename(path))[0]
        return (order.index(name) if name in order else len(order), name)

    for path in sorted(glob.glob(os.path.join(root, "*.json")), key=table_rank):
        try:
            with open(path) as f:
                doc = json.load(f)
        except (OSError, ValueError):
            continue
        if not isinstance(doc, dict) or doc.get("format") != "deformbench-table/1":
            continue
        check_table(path, doc)
        if doc["table"] == "stability":
            continue  # in its own section
        cols = [(c["key"], c["header"]) for c in doc["columns"]]
        table_html.append('<h3 id="table-%s">%s: %s</h3>' % (esc(doc["table"]), esc(doc["table"]),
                                                             esc(doc["title"])))
        if doc.get("source"):
            table_html.append("<p>Paper columns: %s</p>" % esc(doc["source"]))
        links = []
        for r in doc["rows"]:
            sc = r.get("scene") if isinstance(r.get("scene"), str) else None
            case = None
            if sc and sc.startswith("scenes/") and sc.endswith(".json"):
                case = os.path.join("runs", sc[len("scenes/"):-len(".json")])
            links.append(viewer_of(case))
        table_html.append(html_table(cols, doc["rows"], links))
        if doc.get("notes"):
            table_html.append("<ul>%s</ul>" % "".join("<li>%s</li>" % esc(n) for n in doc["notes"]))
    top_results = os.path.join(root, "results.json")
    if os.path.exists(top_results):
        doc, t = results_table(top_results, viewers.get("."))
        table_html.insert(0, '<h3 id="table-results">results: %s</h3>%s'
                          % (esc(doc["scene"]["name"]), t))
    if table_html:
        sections.append(('tables', "Tables", "".join(table_html)))

    # Calibrations (deformbench-calibration/1): the folder's own calibration.json, or one per
    # model folder below it (scripts/calibration_study.sh), defaults and calibrated side by side.
    cal_files = sorted(glob.glob(os.path.join(root, "calibration.json")) +
                       glob.glob(os.path.join(root, "*", "calibration.json")))
    cal_rows = []
    for path in cal_files:
        try:
            with open(path) as f:
                c = json.load(f)
        except (OSError, ValueError):
            continue
        if not isinstance(c, dict) or c.get("format") != "deformbench-calibration/1":
            continue
        check_calibration(path, c)
        scale = 1.0 if c.get("metric") == "loss_ratio" else 1e3
        def val(v):
            return None if v is None else scale * v
        row = {"model": c.get("plugin", "") + "/" + c.get("model", ""),
               "metric": c.get("metric", "") + ("" if scale == 1.0 else " (mm)"),
               "params": ", ".join("%s %.3g (default %.3g)" % (k, v, c.get("defaults", {}).get(k, float("nan")))
                                   for k, v in c.get("params", {}).items()),
               "train_before": val(c["train"]["before"]), "train_after": val(c["train"]["after"]),
               "validation_before": val(c["validation"]["before"]),
               "validation_after": val(c["validation"]["after"]),
               "evaluations": c.get("evaluations"), "wall_s": c.get("wall_s")}
        cal_rows.append(row)
    if cal_rows:
        cols = [("model", "model"), ("metric", "metric"), ("params", "calibrated params"),
                ("train_before", "train default"), ("train_after", "train calibrated"),
                ("validation_before", "validation default"),
                ("validation_after", "validation calibrated"), ("evaluations", "trials"),
                ("wall_s", "wall s")]
        sections.append(("calibration", "Calibration", html_table(cols, cal_rows)))

    # Error against run time.
    sweep_path = os.path.join(root, "sweep.json")
    if os.path.exists(sweep_path):
        with open(sweep_path) as f:
            sweep = json.load(f)
        parts = []
        if HAVE_MPL:
            import subprocess
            png = os.path.join(root, "sweep.png")
            script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "plot_sweep.py")
            subprocess.run([sys.executable, script, sweep_path, png], check=False,
                           stdout=subprocess.DEVNULL)
            if os.path.exists(png):
                parts.append(png_tag(png, "error against run time"))
        rows, links, pts = [], [], []
        runs_folder = os.path.dirname(sweep.get("results", "runs/results.json")) or "."
        href = viewer_of(runs_folder)
        for p in sweep["points"]:
            q = dict(p)
            for k in ("rmse_50", "rmse_all", "max"):
                q[k] = 1e3 * p[k] if p.get(k) is not None else None
            rows.append(q)
            # A sweep run in child processes has one results.json per point.
            own = viewer_of(os.path.dirname(p["results"])) if p.get("results") else None
            link = (own or href) + run_hash(p["label"]) if (own or href) else None
            links.append(link)
            if p.get("status") == "ok" and p.get("ms_median") and p.get("rmse_50"):
                params = {a["param"]: a["value"] for a in (p.get("resolution"), p.get("effort"))
                          if a}
                if not params and p.get("param"):
                    params = {p["param"]: p["value"]}
                run = {"label": p["label"], "model": p["model"], "params": params,
                       "valid": p.get("valid", True), "invalid_reason": p.get("invalid_reason")}
                cal = bool(p.get("calibrated"))
                pts.append({"x": p["ms_median"], "y": 1e3 * p["rmse_50"],
                            "series": p["model"] + (" calibrated" if cal else ""),
                            "model": p["model"], "plugin": p.get("plugin"), "calibrated": cal,
                            "valid": p.get("valid", True),
                            "text": run_point_text(run, p["ms_median"], p["rmse_50"], "rmse_50"),
                            "href": link, "ring": bool(p.get("pareto_overall")),
                            "front": bool(p.get("pareto"))})
        plot = svg_scatter(pts, "ms per step (median)",
                           "rmse_50 (mm), %s" % nearest_label(sweep),
                           sweep.get("haptic_budget_ms"))
        if plot:
            parts.insert(0, "<p>Hover a point for its run; click it to open the run's viewer. "
                         "One colour per model; lines: each model's Pareto front (dashed: "
                         "calibrated, diamonds); black rings: the front over all models; hollow: "
                         "invalid or calibrated; red line: the haptic budget. The PNG below is "
                         "the static version.</p>" + plot)
        summary = []
        for m in sweep.get("models", []):
            e50, eall = m.get("rmse_50") or {}, m.get("rmse_all") or {}
            summary.append({
                "model": m["model"] + (" calibrated" if m.get("calibrated") else ""),
                "axes": " x ".join(a for a in (m.get("resolution_param"), m.get("effort_param"))
                                   if a) or "-",
                "points": "%s of %s" % (m.get("valid_points"), m.get("points")),
                "slope_resolution": e50.get("slope_resolution"),
                "descent_all": (eall.get("descent_resolution") or {}).get("text"),
                "slope_effort": e50.get("slope_effort"),
                "floor_50": (e50.get("floor") or {}).get("text"),
                "floor_all": (eall.get("floor") or {}).get("text")})
        if summary:
            parts.append("<p>Per model: slopes are d ln(rmse_50) / d ln(ms per step) along each "
                         "axis (at the other axis' costliest value); the floor is where the "
                         "error stops falling (the model's own error, not the solver's).</p>")
            parts.append(html_table([("model", "model"), ("axes", "axes"),
                                     ("points", "valid points"),
                                     ("slope_resolution", "slope along resolution"),
                                     ("descent_all", "rmse_all along resolution, to its floor"),
                                     ("slope_effort", "slope along effort"),
                                     ("floor_50", "rmse_50"), ("floor_all", "rmse_all")],
                                    summary))
        check = sweep.get("reference_check")
        if check:
            said = html.escape(check["summary"] + ("; warning: " + check["warning"]
                                                   if check.get("warning") else ""))
        else:
            said = ("not estimated (no check of it in the cache: <code>deformbench converge "
                    "SCENE --out DIR --of-reference</code> makes one)")
        parts.append("<p>The reference's own discretisation error, the yardstick of every "
                     "floor above: %s.</p>" % said)
        for r in rows:
            if r.get("valid") is False:
                r["status"] = "invalid (%s)" % r.get("invalid_reason", "")
        parts.append(html_table([("label", "point"), ("status", "status"),
                                 ("ms_median", "ms/step"), ("rmse_50", "rmse_50 mm"),
                                 ("rmse_all", "rmse_all mm"), ("pareto", "model's front"),
                                 ("pareto_overall", "overall front")], rows, links))
        sections.append(("sweep", "Error against run time", "".join(parts)))

    # Stability.
    stab_path = os.path.join(root, "stability.json")
    if os.path.exists(stab_path):
        with open(stab_path) as f:
            stab = json.load(f)
        parts = []
        models = []
        for r in stab["rows"]:
            if r["model"] not in models:
                models.append(r["model"])
        summary = []
        for m in models:
            mine = [r for r in stab["rows"] if r["model"] == m]
            row = {"model": m}
            for s in ("stable", "diverged", "failed", "unsupported"):
                row[s] = sum(1 for r in mine if r["status"] == s)
            summary.append(row)
        parts.append(html_table([("model", "model"), ("stable", "stable"),
                                 ("diverged", "diverged"), ("failed", "failed"),
                                 ("unsupported", "unsupported")], summary))
        if HAVE_MPL:
            import subprocess
            script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "plot_stability.py")
            subprocess.run([sys.executable, script, stab_path, root], check=False,
                           stdout=subprocess.DEVNULL)
            for m in models:
                png = os.path.join(root, "stability_%s.png" % m)
                if os.path.exists(png):
                    parts.append('<div class="map">%s</div>' % png_tag(png, "stability map " + m))
        cols = [(c["key"], c["header"]) for c in stab["columns"] if c["key"] != "scene"]
        links = [viewer_of(os.path.join("runs", str(r.get("model")), str(r.get("case"))))
                 for r in stab["rows"]]
        parts.append("<details><summary>every case</summary>%s</details>"
                     % html_table(cols, stab["rows"], links))
        sections.append(("stability", "Stability", "".join(parts)))

    # Deformed organs: every results.json below the folder that has final surfaces.
    if HAVE_MPL:
        found = glob.glob(os.path.join(root, "**", "results.json"), recursive=True)

        def organ_rank(path):
            # The folder's own results first, then the runs compared with a FEM reference
            # (method comparison, hybrid), then the rest, each alphabetically.
            rel = os.path.relpath(path, root)
            group = 0 if rel == "results.json" else 1 if "/method/" in "/" + rel else \
                2 if "/hybrid/" in "/" + rel else 3
            return (group, rel)

        found.sort(key=organ_rank)
        figs = []
        for path in found:
            if len(figs) >= MAX_ORGAN_FIGURES:
                notes.append("organ pictures limited to the first %d results folders"
                             % MAX_ORGAN_FIGURES)
                break
            try:
                fig, caption = organ_figure(path)
            except Exception as e:  # a broken results folder must not stop the report
                notes.append("%s: no picture (%s)" % (os.path.relpath(path, root), e))
                continue
            if fig is None:
                continue
            figs.append("<figure><figcaption>%s (%s)</figcaption>%s</figure>"
                        % (esc(caption), esc(os.path.relpath(path, root)),
                           png_tag(fig, caption)))
        if figs:
            sections.append(("organs", "Deformed organs", "".join(figs)))

    title = "deformbench report: %s" % os.path.abspath(root)
    body = ["<h1>%s</h1>" % esc(title)]
    for n in notes:
        body.append('<p class="note">%s</p>' % esc(n))
    body.append("<nav>%s</nav>" % " | ".join('<a href="#%s">%s</a>' % (i, esc(t))
                                              for i, t, _ in sections))
    for i, t, content in sections:
        body.append('<section id="%s"><h2>%s</h2>%s</section>' % (i, esc(t), content))
    if not sections:
        body.append("<p>Nothing to report in this folder (no results.json, tables, sweep.json or "
                    "stability.json).</p>")
    style = """
body { font-family: sans-serif; margin: 1.5em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 12px; }
th, td { border: 1px solid #ccc; padding: 2px 6px; text-align: right; }
th { background: #eee; }
td:first-child { text-align: left; }
.st-ok, .st-stable { background: #e8f5e9; }
.st-diverged { background: #fff3e0; }
.st-failed, .st-missing { background: #ffebee; }
.st-unsupported, .st-skipped { background: #f5f5f5; }
img { max-width: 100%; }
.map { display: inline-block; margin: 4px; }
.map img { width: 560px; }
.note { color: #a33; }
figure { margin: 1.5em 0; border-top: 1px solid #ddd; }
figcaption { font-weight: bold; margin: 0.4em 0; }
"""
    doc = ("<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>%s</title><style>%s</style>"
           "%s</head><body>%s</body></html>" % (esc(title), style, viewer_head, "\n".join(body)))
    tmp = out + ".tmp"
    with open(tmp, "w") as f:
        f.write(doc)
    os.replace(tmp, out)
    print("report: %s (%d sections, %.2f MB%s)" % (
        out, len(sections), os.path.getsize(out) / 1e6,
        "" if HAVE_MPL else ", no pictures: matplotlib missing"))
    sub = len(viewers) - (1 if "." in viewers else 0)
    if sub:
        print("viewers: %d viewer.html beside the results.json below %s, sharing %s (%.2f MB "
              "together)" % (sub, root, VIEWER_LIB, viewer_bytes / 1e6))
    return 0


if __name__ == "__main__":
    sys.exit(main())
