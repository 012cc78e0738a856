#!/usr/bin/env python3
"""Compares two `deformbench tables` output folders on everything but timing.

Usage: compare_tables.py BEFORE AFTER
For each <table>.json in BEFORE: the same columns, the same notes (the checkout's path of shipped
data masked), and row by row the same cells except the timing ones (keys ending in _ms or _s,
and "ms", that are not the paper's figures).
The generated scenes (scenes/**.json) must be byte-identical. Prints one line per difference and
exits 1 when there is any.
"""
import json
import re
import pathlib
import sys


def timing(key):
    return not key.startswith("paper_") and (key == "ms" or key.startswith("ms_") or key.endswith("_ms") or key.endswith("_s"))


def checkout_free(value):
    """A table's notes with the checkout's path of shipped data (e.g. the Truth Cube's bead
    file, printed as read) masked: two checkouts of one commit print different paths."""
    if isinstance(value, list):
        return [checkout_free(v) for v in value]
    if isinstance(value, str):
        return re.sub(r"/\S*?/data/", "<checkout>/data/", value)
    return value


def main(before, after):
    before, after = pathlib.Path(before), pathlib.Path(after)
    diffs = []
    tables = sorted(before.glob("*.json"))
    for tb in tables:
        ta = after / tb.name
        if not ta.exists():
            diffs.append(f"{tb.name}: missing after")
            continue
        b, a = json.loads(tb.read_text()), json.loads(ta.read_text())
        for k in ("format", "table", "title", "source", "columns", "notes"):
            if checkout_free(b.get(k)) != checkout_free(a.get(k)):
                diffs.append(f"{tb.name}: {k} differs")
        if len(b["rows"]) != len(a["rows"]):
            diffs.append(f"{tb.name}: {len(b['rows'])} rows before, {len(a['rows'])} after")
        for i, (rb, ra) in enumerate(zip(b["rows"], a["rows"])):
            for k in sorted(set(rb) | set(ra)):
                if timing(k):
                    continue
                if rb.get(k) != ra.get(k):
                    diffs.append(f"{tb.name}: row {i} {k}: {rb.get(k)!r} -> {ra.get(k)!r}")
    scenes = sorted(p.relative_to(before) for p in (before / "scenes").rglob("*.json"))
    for s in scenes:
        if not (after / s).exists() or (after / s).read_bytes() != (before / s).read_bytes():
            diffs.append(f"{s}: differs or missing after")
    for d in diffs:
        print(d)
    print(f"{len(tables)} tables, {len(scenes)} scenes compared: "
          f"{'identical (non-timing)' if not diffs else str(len(diffs)) + ' differences'}")
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
