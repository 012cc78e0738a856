"""Shared helpers of the deformbench plotting scripts (matplotlib, headless)."""
import sys

NO_MATPLOTLIB = 3  # exit code the deformbench program recognises


def pyplot_or_exit():
    """Returns matplotlib.pyplot with the headless Agg backend, or exits with NO_MATPLOTLIB."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        return plt
    except ImportError:
        print("matplotlib is not installed for %s" % sys.executable)
        sys.exit(NO_MATPLOTLIB)


def plot_args(doc_string):
    """The (json document, output path) of a plotting script's command line `IN.json OUT`; prints
    the script's usage (doc_string) and exits 2 on any other."""
    if len(sys.argv) != 3:
        print(doc_string)
        sys.exit(2)
    import json
    with open(sys.argv[1]) as f:
        return json.load(f), sys.argv[2]


STATUS_COLOURS = {
    "stable": "#4caf50",
    "diverged": "#ff9800",
    "failed": "#d32f2f",
    "unsupported": "#9e9e9e",
}

# One colour per model in every plot and report (issue H4 item 6): the shipped plugins by name,
# any other model by a stable hash of its name into the second palette.
MODEL_COLOURS = {
    "pbd": "#1f77b4",
    "massspring": "#ff7f0e",
    "fem_hex": "#2ca02c",
    "hybrid_fem_pbd": "#d62728",
    "metaballs": "#9467bd",
    "particle_bem": "#8c564b",
    "bullet_softbody": "#e377c2",
    "bullet_deformable": "#7f7f7f",
    "reference_fem": "#bcbd22",
    "calculix": "#17becf",
}
OTHER_COLOURS = ["#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173", "#3182bd", "#e6550d",
                 "#31a354", "#756bb1", "#636363"]


def model_colour(model, plugin=None):
    """The colour of a model (its name, else its plugin's, else a hash of the name)."""
    for key in (model, plugin):
        if key in MODEL_COLOURS:
            return MODEL_COLOURS[key]
    import zlib
    return OTHER_COLOURS[zlib.crc32((model or plugin or "").encode()) % len(OTHER_COLOURS)]


def nearest_label(doc, k=50):
    """'50 vertices nearest the grasp' (or the load, tool, plate) from a sweep.json."""
    return "%d vertices nearest the %s" % (k, doc.get("nearest_to") or "load")
