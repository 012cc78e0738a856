#!/usr/bin/env python3
"""Error against run time from a deformbench sweep.json.

usage: plot_sweep.py SWEEP.json OUT.png

Two panels (rmse_50 and rmse_all against the median ms per step, log-log where the data span a
decade). Every model has one colour (the same in the HTML report): its points are dots (hollow
diamonds when calibrated, crosses when invalid), its Pareto front a line through them (dashed
when calibrated), and a reached floor a dotted level in its colour. Each point is labelled with its axis values; the 1 ms
haptic budget is a red vertical line.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from deform_plot_common import (model_colour, nearest_label, plot_args,  # noqa: E402
                                pyplot_or_exit)


def axis_text(p):
    """The point's axis values, short: '967/1e-3' (resolution/effort), or the one value."""
    vals = []
    for key in ("resolution", "effort"):
        a = p.get(key)
        if a:
            v = a["value"]
            vals.append(v if isinstance(v, str) else "%g" % v)
    if not vals and p.get("param"):
        v = p.get("value")
        vals.append(v if isinstance(v, str) else "%g" % v)
    return "/".join(vals)


def curves(doc):
    """(model, plugin, calibrated) of each curve, in the points' order."""
    out = []
    for p in doc["points"]:
        key = (p["model"], p.get("plugin"), bool(p.get("calibrated")))
        if key not in out:
            out.append(key)
    return out


def floors(doc, metric):
    """{(model, calibrated): floor in m} for the models whose floor the sweep reached."""
    out = {}
    for m in doc.get("models", []):
        f = (m.get(metric) or {}).get("floor") or {}
        if f.get("reached") and f.get("error_m") is not None:
            out[(m["model"], bool(m.get("calibrated")))] = f["error_m"]
    return out


def draw_panel(ax, doc, points, key, title, budget):
    reached = floors(doc, key)
    for model, plugin, calibrated in curves(doc):
        colour = model_colour(model, plugin)
        pts = sorted([p for p in points if p["model"] == model and p.get("plugin") == plugin
                      and bool(p.get("calibrated")) == calibrated and p[key] is not None],
                     key=lambda p: p["ms_median"])
        if not pts:
            continue
        name = model + (" calibrated" if calibrated else "")
        marker = dict(marker="D", markerfacecolor="white") if calibrated else dict(marker="o")
        good = [p for p in pts if p.get("valid", True)]
        bad = [p for p in pts if not p.get("valid", True)]
        if good:
            ax.plot([p["ms_median"] for p in good], [1e3 * p[key] for p in good],
                    linestyle="none", color=colour, markersize=5, label=name, **marker)
        if bad:  # listed, never ranked
            ax.plot([p["ms_median"] for p in bad], [1e3 * p[key] for p in bad], linestyle="none",
                    marker="x", color=colour, markersize=6, label=name + " (invalid)")
        for p in pts:
            text = axis_text(p)
            if text:
                ax.annotate(text, (p["ms_median"], 1e3 * p[key]), textcoords="offset points",
                            xytext=(4, 4), fontsize=6, color=colour)
        # The model's own front: on rmse_50 the flags of sweep.json, on rmse_all its own.
        front = [p for p in pts if p.get("pareto")] if key == "rmse_50" else [
            p for p in good if not any(
                q is not p and q["ms_median"] <= p["ms_median"] and q[key] <= p[key]
                and (q["ms_median"] < p["ms_median"] or q[key] < p[key]) for q in good)]
        if len(front) > 1:
            ax.plot([p["ms_median"] for p in front], [1e3 * p[key] for p in front],
                    "--" if calibrated else "-", color=colour, linewidth=1.5)
        if (model, calibrated) in reached:
            ax.axhline(1e3 * reached[(model, calibrated)], color=colour, linestyle=":",
                       linewidth=1)
    ax.axvline(budget, color="red", linestyle=":", linewidth=1.5,
               label="%g ms haptic budget" % budget)
    # Log axes only where the data span a decade; otherwise the ticks are unreadable.
    xs_all = [p["ms_median"] for p in points] + [budget]
    ys_all = [1e3 * p[key] for p in points if p[key] is not None and p[key] > 0]
    if xs_all and min(xs_all) > 0 and max(xs_all) / min(xs_all) > 10:
        ax.set_xscale("log")
    if ys_all and max(ys_all) / min(ys_all) > 10:
        ax.set_yscale("log")
    ax.set_xlabel("median ms per step")
    ax.set_ylabel("error (mm)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)


def main():
    doc, out = plot_args(__doc__)
    plt = pyplot_or_exit()
    points = [p for p in doc["points"]
              if p["status"] == "ok" and p["ms_median"] is not None and p["rmse_50"] is not None]
    budget = doc.get("haptic_budget_ms", 1.0)
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    draw_panel(axes[0], doc, points, "rmse_50", "rmse_50 (%s)" % nearest_label(doc), budget)
    draw_panel(axes[1], doc, points, "rmse_all", "rmse_all (every surface vertex)", budget)
    fig.suptitle("Error against run time: %s (reference %s); lines: each model's Pareto front, "
                 "dotted: its floor" % (doc["scene"]["name"], doc.get("reference", "?")),
                 fontsize=10)
    skipped = [p["label"] + ": " + p["status"] for p in doc["points"] if p not in points]
    if skipped:
        fig.text(0.01, 0.01, "not plotted: " + "; ".join(skipped)[:300], fontsize=7)
    fig.tight_layout(rect=(0, 0.03, 1, 0.95))
    fig.savefig(out, dpi=110)
    print("plot: " + out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
