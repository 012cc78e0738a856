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


STATUS_COLOURS = {
    "stable": "#4caf50",
    "diverged": "#ff9800",
    "failed": "#d32f2f",
    "unsupported": "#9e9e9e",
}
