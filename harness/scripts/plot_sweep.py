#!/usr/bin/env python3
"""Error against run time from a deformbench sweep.json.

usage: plot_sweep.py SWEEP.json OUT.png

Two panels (rmse_50 and rmse_all against the median ms per step, log-log), one curve per model
through its knob values (labelled), the Pareto front of rmse_50 against time over all points
marked, and the 1 ms haptic budget drawn as a vertical line.
"""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from deform_plot_common import pyplot_or_exit  # noqa: E402


def main():
    if len(sys.argv) != 3:
        print(__doc__)
        return 2
    with open(sys.argv[1]) as f:
        doc = json.load(f)
    plt = pyplot_or_exit()
    points = [p for p in doc["points"]
              if p["status"] == "ok" and p["ms_median"] is not None and p["rmse_50"] is not None]
    budget = doc.get("haptic_budget_ms", 1.0)
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    def series(p):  # a model's default curve, and its calibrated one (sweep --calibration)
        return p["model"] + (" calibrated" if p.get("calibrated") else "")
    models = []
    for p in doc["points"]:
        if series(p) not in models:
            models.append(series(p))
    cmap = plt.get_cmap("tab10")
    for ax, key, title in ((axes[0], "rmse_50", "rmse_50 (50 vertices nearest the load)"),
                           (axes[1], "rmse_all", "rmse_all (every surface vertex)")):
        for i, m in enumerate(models):
            pts = sorted([p for p in points if series(p) == m and p[key] is not None],
                         key=lambda p: p["ms_median"])
            if not pts:
                continue
            xs = [p["ms_median"] for p in pts]
            ys = [1e3 * p[key] for p in pts]
            ax.plot(xs, ys, "--o" if m.endswith(" calibrated") else "-o", color=cmap(i % 10),
                    label=m, markersize=5)
            for p, x, y in zip(pts, xs, ys):
                if p["param"]:
                    v = p["value"]
                    text = v if isinstance(v, str) else str(v)
                    ax.annotate(text.replace("_euler", ""), (x, y), textcoords="offset points",
                                xytext=(4, 4), fontsize=7, color=cmap(i % 10))
        if key == "rmse_50":
            front = sorted([p for p in points if p.get("pareto")], key=lambda p: p["ms_median"])
            if front:
                ax.plot([p["ms_median"] for p in front], [1e3 * p["rmse_50"] for p in front],
                        "--", color="black", linewidth=1, zorder=0)
                ax.scatter([p["ms_median"] for p in front], [1e3 * p["rmse_50"] for p in front],
                           s=120, facecolors="none", edgecolors="black", label="Pareto front",
                           zorder=5)
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
        ax.legend(fontsize=8)
    fig.suptitle("Error against run time: %s (reference %s)"
                 % (doc["scene"]["name"], doc.get("reference", "?")))
    skipped = [p["label"] + ": " + p["status"] for p in doc["points"] if p not in points]
    if skipped:
        fig.text(0.01, 0.01, "not plotted: " + "; ".join(skipped)[:300], fontsize=7)
    fig.tight_layout(rect=(0, 0.03, 1, 0.95))
    fig.savefig(sys.argv[2], dpi=110)
    print("plot: " + sys.argv[2])
    return 0


if __name__ == "__main__":
    sys.exit(main())
