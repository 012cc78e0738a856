#!/usr/bin/env python3
"""Size bound and round trip of the viewer's surface encoding, without a simulation.

9 models and a reference, 8066 vertices, 100 frames of a smooth lift with a travelling wobble
(synthetic, in memory): the viewer page must stay under 30 MB with every frame kept, and the
decoded positions (this script mirrors viewer.js's decoder) must be within half a quantisation
step of the originals. A budget too small for the frames must thin them and say so.
Exit 77 (ctest: skipped) without three.js.
"""
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "harness", "scripts"))
import viewer_data  # noqa: E402
from synthetic_results import sphere, lifted  # noqa: E402

import base64  # noqa: E402
import zlib  # noqa: E402


def decode(run, n, rest):
    """viewer.js's decodeRun + Series.at, in numpy: (F, n, 3) positions."""
    raw = np.frombuffer(zlib.decompress(base64.b64decode(run["data"])), dtype=np.uint8)
    half = raw.size // 2
    q = (raw[:half].astype(np.uint16) | (raw[half:].astype(np.uint16) << 8)).view(np.int16)
    d = q.reshape(-1, 3, n).astype(np.int64)
    q = np.cumsum(d, axis=0)
    q = ((q + 32768) % 65536 - 32768)  # the int16 wrap of the decoder
    base = rest if run["base"] is None else np.frombuffer(
        zlib.decompress(base64.b64decode(run["base"])), dtype="<f4").reshape(-1, 3)
    return base[None, :, :] + q.transpose(0, 2, 1) * np.array(run["scale"])[None, None, :]


def main():
    try:
        viewer_data.viewer_assets()
    except OSError as e:
        print("SKIP: %s" % e)
        return 77
    V, F = sphere(64)
    n, frames, models = len(V), 100, 9
    t = np.linspace(0, 1, frames)
    runs = []
    for k in range(models + 1):
        role = "reference" if k == 0 else "model"
        gain = 1.0 + 0.1 * k
        series = []
        for j, tf in enumerate(t):
            x = lifted(V, 0.025 * gain, tf)
            wobble = 0.001 * k * np.sin(40 * V[:, 0] + 12 * tf) * np.exp(-3 * tf)
            x[:, 1] += wobble
            series.append((float(0.01 * j), x))
        rec = {"label": "m%d" % k if k else "reference", "model": "m%d" % k, "role": role,
               "status": "ok", "params": {"gain": gain}, "step_ms": {"median": 0.1 * k}}
        runs.append((rec, series))
    doc = {"scene": {"name": "size-bound"}}
    t0 = time.time()
    data = viewer_data.build(doc, V, F, runs)
    head, body = viewer_data.page_parts(data)
    size = len(head) + len(body)
    print("%d runs x %d vertices x %d frames: page %.2f MB (surfaces %.2f MB), %.1f s"
          % (len(runs), n, frames, size / 1e6, data["encoded_bytes"] / 1e6, time.time() - t0))
    fails = []
    if size >= 30e6:
        fails.append("page %.1f MB, the bound is 30 MB" % (size / 1e6))
    if data["thinned"] or len(data["times"]) != frames:
        fails.append("frames were thinned (%s) though the budget fits them" % data["thinned"])
    rest = V.astype(np.float32)
    for (rec, series), run in zip(runs[:3], data["runs"][:3]):
        got = decode(run, n, rest)
        want = np.stack([x for _, x in series])
        err = np.abs(got - want).max(axis=(0, 1))
        step = np.array(run["scale"])
        if (err > 0.5 * step + 1e-7).any():
            fails.append("%s: decoding error %s > half a step %s" % (rec["label"], err, step / 2))
    # A budget below the data: frames thinned, the last kept, and the viewer told.
    small = viewer_data.build(doc, V, F, runs[:3], budget=data["encoded_bytes"] // 20)
    if not small["thinned"] or small["times"][-1] != data["times"][-1]:
        fails.append("a small budget did not thin the frames keeping the last one")
    fails += validity_marks()
    for f in fails:
        print("FAIL: " + f)
    return 1 if fails else 0


def validity_marks():
    """Issue 35 item 7 and issue 33 item 7: a failed run is never shown valid, even when an old
    results.json says so; errors against an invalid reference say so in the viewer's data and
    the report's run table."""
    import json
    import tempfile
    import report  # noqa: E402
    fails = []
    failed = {"label": "f", "model": "f", "status": "failed", "valid": True, "message": "init: x"}
    against = {"label": "m", "model": "m", "status": "ok", "valid": True,
               "reference_valid": False, "reference_invalid_reason": "the reference r is invalid: 2 solves did not converge",
               "error": {"rmse_all": 0.001}, "step_ms": {"median": 0.1}}
    if viewer_data._run_entry(failed, [0.0], [1, 1, 1], "", {}, None, "")["valid"] is not False:
        fails.append("viewer: a failed run written valid: true is shown valid")
    entry = viewer_data._run_entry(against, [0.0], [1, 1, 1], "", {}, None, "")
    if entry.get("reference_valid") is not False or "2 solves" not in (entry.get("reference_invalid_reason") or ""):
        fails.append("viewer: reference_valid false is not passed on")
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "results.json")
        with open(path, "w") as f:
            json.dump({"format": "deformbench-results/1", "scene": {"name": "marks"},
                       "runs": [failed, against]}, f)
        _, html = report.results_table(path)
    if "against an invalid reference" not in html:
        fails.append("report: the run table does not say 'against an invalid reference'")
    if html.count(">no<") < 1:
        fails.append("report: a failed run written valid: true is shown valid")
    return fails


if __name__ == "__main__":
    sys.exit(main())
