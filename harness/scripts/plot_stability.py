#!/usr/bin/env python3
"""Stability maps from a deformbench stability.json.

usage: plot_stability.py STABILITY.json OUTDIR

One picture per model, OUTDIR/stability_<model>.png: the map of Young's modulus against the time
step (cells coloured by verdict: accurate / inaccurate, with its reason / collapsed / diverged, with
the step / failed / unchecked, with its reason; by status for a stability.json without verdicts), and a strip of the other
cases (Poisson ratio, large forces, cantilever, scale, slivers, pull, invert, flatten).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from deform_plot_common import STATUS_COLOURS, plot_args, pyplot_or_exit  # noqa: E402

VERDICT_COLOURS = {
    "accurate": "#4caf50",
    "inaccurate": "#fff176",
    "collapsed": "#ab47bc",
    "diverged": "#ff9800",
    "failed": "#d32f2f",
    "unchecked": "#bbdefb",
}


def colour(r):
    if r.get("verdict"):
        return VERDICT_COLOURS.get(r["verdict"], "white")
    return STATUS_COLOURS.get(r["status"], "white")


def label(r):
    text = r.get("verdict") or r["status"]
    if text == "inaccurate" and r.get("reason"):
        text += "\n" + r["reason"].replace("_", " ")
    if r.get("error_ratio") is not None and text != "unchecked":
        text += "\nerr %.2g" % r["error_ratio"]
    if r["status"] == "diverged" and r.get("step") is not None:
        text += "\nstep %d" % r["step"]
    if text == "unchecked" and r["status"] != "stable":
        text += "\n(%s)" % r["status"]
    elif text == "unchecked" and r.get("reason"):
        text += "\n(%s)" % r["reason"].replace("reference not converged", "ref. not conv.")
    return text


def main():
    doc, out = plot_args(__doc__)
    plt = pyplot_or_exit()
    from matplotlib.patches import Patch, Rectangle

    rows = doc["rows"]
    models = []
    for r in rows:
        if r["model"] not in models:
            models.append(r["model"])
    written = []
    for model in models:
        mine = [r for r in rows if r["model"] == model]
        grid = [r for r in mine if r["group"] == "stiffness_dt"]
        others = [r for r in mine if r["group"] != "stiffness_dt"]
        youngs = sorted({r["young"] for r in grid})
        dts = sorted({r["dt"] for r in grid})
        fig, (ax, ax2) = plt.subplots(
            2, 1, figsize=(max(8, 0.75 * len(others)), 7), gridspec_kw={"height_ratios": [max(len(dts), 1), 1.2]})
        for r in grid:
            x, y = youngs.index(r["young"]), dts.index(r["dt"])
            ax.add_patch(Rectangle((x, y), 1, 1, facecolor=colour(r), edgecolor="white",
                                   linewidth=2))
            ax.text(x + 0.5, y + 0.5, label(r), ha="center", va="center", fontsize=7)
        ax.set_xlim(0, max(len(youngs), 1))
        ax.set_ylim(0, max(len(dts), 1))
        ax.set_xticks([i + 0.5 for i in range(len(youngs))])
        ax.set_xticklabels(["%g" % e for e in youngs])
        ax.set_yticks([i + 0.5 for i in range(len(dts))])
        ax.set_yticklabels(["1/%d" % round(1 / d) if d > 0 else "%g" % d for d in dts])
        ax.set_xlabel("Young's modulus E (Pa)")
        ax.set_ylabel("time step dt (s)")
        ax.set_title("%s: stability and accuracy map (1 N load, gravity)" % model)
        for i, r in enumerate(others):
            ax2.add_patch(Rectangle((i, 0), 1, 1, facecolor=colour(r), edgecolor="white",
                                    linewidth=2))
            ax2.text(i + 0.5, 0.5, label(r), ha="center", va="center", fontsize=6)
        ax2.set_xlim(0, max(len(others), 1))
        ax2.set_ylim(0, 1)
        ax2.set_xticks([i + 0.5 for i in range(len(others))])
        ax2.set_xticklabels([r["case"] for r in others], fontsize=6, rotation=30, ha="right")
        ax2.set_yticks([])
        ax2.set_title("other cases", fontsize=10)
        verdicts = any(r.get("verdict") for r in mine)
        legend = VERDICT_COLOURS if verdicts else STATUS_COLOURS
        handles = [Patch(facecolor=c, label=s) for s, c in legend.items()]
        fig.legend(handles=handles, loc="lower center", ncol=5, fontsize=8)
        fig.tight_layout(rect=(0, 0.05, 1, 1))
        path = os.path.join(out, "stability_%s.png" % model)
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)
    print("stability maps: " + ", ".join(os.path.basename(p) for p in written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
