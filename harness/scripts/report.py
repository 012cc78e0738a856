#!/usr/bin/env python3
"""A self-contained HTML report of a deformbench folder (results, tables, sweep or stability).

usage: report.py DIR OUT.html

Sections (each present when the folder has its data):
  tables          every <table>.json (format deformbench-table/1), and results.json run tables
  sweep           error against run time (sweep.json; the plot is drawn again with matplotlib)
  stability       the stability table summary and one stability map per model
  organs          the final deformed organ of each model side by side, coloured by the distance
                  to the reference's final surface (matplotlib 3D render of final.obj)
Images are PNG embedded as base64, so the file opens anywhere. Without matplotlib the report is
written without pictures and says so.
"""
import base64
import glob
import html
import io
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    HAVE_MPL = True
except ImportError:
    HAVE_MPL = False

MAX_ORGAN_FIGURES = 12


def esc(x):
    return html.escape(str(x))


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


def html_table(columns, rows):
    out = ["<table><thead><tr>"]
    out += ["<th>%s</th>" % esc(h) for _, h in columns]
    out.append("</tr></thead><tbody>")
    for r in rows:
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
    with open(results_path) as f:
        doc = json.load(f)
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
    vmax = 0.0
    for r in panels:
        v, fcs = read_obj(os.path.join(base, r["final_surface"]))
        v = np.array(v)
        fcs = np.array(fcs)
        err = None
        if ref_v is not None and r is not ref:
            n = min(len(v), len(ref_v))
            err = np.zeros(len(v))
            err[:n] = np.linalg.norm(v[:n] - ref_v[:n], axis=1) * 1e3
            vmax = max(vmax, float(np.percentile(err[:n], 99)))
        surfaces.append((r, v, fcs, err))
    vmax = vmax if vmax > 0 else 1.0
    cols = len(surfaces)
    fig = plt.figure(figsize=(3.4 * cols + 1.2, 3.8))
    cmap = plt.get_cmap("viridis")
    lo = np.min([s[1].min(axis=0) for s in surfaces], axis=0)
    hi = np.max([s[1].max(axis=0) for s in surfaces], axis=0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    for i, (r, v, fcs, err) in enumerate(surfaces):
        ax = fig.add_subplot(1, cols, i + 1, projection="3d")
        tris = v[fcs]
        if err is not None:
            face_err = err[fcs].mean(axis=1)
            colours = cmap(np.clip(face_err / vmax, 0, 1))
        else:
            colours = [(0.85, 0.55, 0.5, 1.0)] * len(fcs)
        coll = Poly3DCollection(tris, facecolors=colours, edgecolors="none", linewidths=0)
        ax.add_collection3d(coll)
        for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
            setter(c - half, c + half)
        ax.view_init(elev=25, azim=-60)
        ax.set_axis_off()
        title = r["label"] + (" [reference]" if r is ref else "")
        if r.get("error") and r["error"].get("rmse_all") is not None:
            title += "\nrmse_all %.3g mm" % (1e3 * r["error"]["rmse_all"])
        ax.set_title(title, fontsize=8)
    if ref_v is not None:
        sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, vmax))
        fig.colorbar(sm, ax=fig.axes, shrink=0.7, label="distance to reference (mm)")
    caption = "%s: final surfaces%s" % (
        doc["scene"]["name"],
        ", coloured by distance to the reference (%s)" % ref["label"] if ref else
        " (no reference: uniform colour)")
    return fig, caption


def results_table(path):
    with open(path) as f:
        doc = json.load(f)
    rows = []
    for r in doc["runs"]:
        e = r.get("error") or {}
        sm = r.get("step_ms") or {}
        rows.append({
            "label": r["label"] + (" [ref]" if r.get("role") == "reference" else ""),
            "status": (r["status"] if r.get("valid", True)
                       else "invalid (%s)" % r.get("invalid_reason", "")),
            "ms": sm.get("median"),
            "p95": sm.get("p95"),
            "precompute_s": r.get("precompute_s"),
            "rmse_10": 1e3 * e["rmse_10"] if e.get("rmse_10") is not None else None,
            "rmse_50": 1e3 * e["rmse_50"] if e.get("rmse_50") is not None else None,
            "rmse_all": 1e3 * e["rmse_all"] if e.get("rmse_all") is not None else None,
            "loss_ratio": e.get("loss_ratio"),
            "message": r.get("message", ""),
        })
    cols = [("label", "run"), ("status", "status"), ("ms", "ms/step"), ("p95", "p95 ms"),
            ("precompute_s", "precompute s"), ("rmse_10", "rmse_10 mm"),
            ("rmse_50", "rmse_50 mm"), ("rmse_all", "rmse_all mm"), ("loss_ratio", "loss ratio"),
            ("message", "message")]
    return doc, html_table(cols, rows)


def main():
    if len(sys.argv) != 3:
        print(__doc__)
        return 2
    root, out = sys.argv[1], sys.argv[2]
    if not os.path.isdir(root):
        print("%s: not a folder" % root)
        return 2
    sections = []
    notes = []
    if not HAVE_MPL:
        notes.append("matplotlib is not installed for %s: the report has no pictures."
                     % sys.executable)

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
        if doc["table"] == "stability":
            continue  # in its own section
        cols = [(c["key"], c["header"]) for c in doc["columns"]]
        table_html.append('<h3 id="table-%s">%s: %s</h3>' % (esc(doc["table"]), esc(doc["table"]),
                                                             esc(doc["title"])))
        if doc.get("source"):
            table_html.append("<p>Paper columns: %s</p>" % esc(doc["source"]))
        table_html.append(html_table(cols, doc["rows"]))
        if doc.get("notes"):
            table_html.append("<ul>%s</ul>" % "".join("<li>%s</li>" % esc(n) for n in doc["notes"]))
    top_results = os.path.join(root, "results.json")
    if os.path.exists(top_results):
        doc, t = results_table(top_results)
        table_html.insert(0, '<h3 id="table-results">results: %s</h3>%s'
                          % (esc(doc["scene"]["name"]), t))
    if table_html:
        sections.append(('tables', "Tables", "".join(table_html)))

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
        rows = []
        for p in sweep["points"]:
            q = dict(p)
            for k in ("rmse_50", "rmse_all", "max"):
                q[k] = 1e3 * p[k] if p[k] is not None else None
            rows.append(q)
        for r in rows:
            if r.get("valid") is False:
                r["status"] = "invalid (%s)" % r.get("invalid_reason", "")
        parts.append(html_table([("label", "point"), ("status", "status"),
                                 ("ms_median", "ms/step"), ("rmse_50", "rmse_50 mm"),
                                 ("rmse_all", "rmse_all mm"), ("pareto", "Pareto")], rows))
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
        parts.append("<details><summary>every case</summary>%s</details>"
                     % html_table(cols, stab["rows"]))
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
           "</head><body>%s</body></html>" % (esc(title), style, "\n".join(body)))
    tmp = out + ".tmp"
    with open(tmp, "w") as f:
        f.write(doc)
    os.replace(tmp, out)
    print("report: %s (%d sections%s)" % (out, len(sections),
                                          "" if HAVE_MPL else ", no pictures: matplotlib missing"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
