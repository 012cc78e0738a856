#!/usr/bin/env python3
"""`report` on broken results folders (issue 35): one line naming the file and the field, exit 2,
never a traceback; surfaces that are not the ones results.json describes are refused; a label
with "<!--<script>" cannot break the viewer's embedded JSON.

usage: report_input_test.py WORK_DIR
"""
import copy
import hashlib
import json
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPTS = os.path.join(HERE, "..", "..", "harness", "scripts")
sys.path.insert(0, SCRIPTS)

OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"


def folder(work, name, doc, obj=OBJ):
    d = os.path.join(work, name)
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(os.path.join(d, "a"))
    with open(os.path.join(d, "a", "final.obj"), "w") as f:
        f.write(obj)
    with open(os.path.join(d, "results.json"), "w") as f:
        json.dump(doc, f)
    return d


def report(d):
    p = subprocess.run([sys.executable, os.path.join(SCRIPTS, "report.py"), d,
                        os.path.join(d, "report.html")], capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


def main():
    work = sys.argv[1]
    os.makedirs(work, exist_ok=True)
    good = {"format": "deformbench-results/1", "scene": {"name": "t"},
            "organ": {"vertices": 4},
            "runs": [{"label": "a", "model": "pbd", "status": "ok", "role": "model",
                      "params": {}, "valid": True, "precompute_s": 0.1,
                      "step_ms": {"median": 0.1, "p95": 0.2},
                      "error": {"rmse_all": 0.001, "max": 0.002, "loss_ratio": 0.1},
                      "final_surface": "a/final.obj", "final_surface_vertices": 4,
                      "final_surface_sha256": hashlib.sha256(OBJ.encode()).hexdigest()}]}
    failures = []

    def expect(name, doc, want_rc, want_text, obj=OBJ):
        rc, out = report(folder(work, name, doc, obj))
        lines = [line for line in out.splitlines() if line.strip()]
        ok = rc == want_rc and want_text in out and "Traceback" not in out
        if want_rc != 0:
            ok = ok and len(lines) == 1
        if not ok:
            failures.append("%s: exit %d, output:\n%s" % (name, rc, out))

    expect("good", good, 0, "report:")
    bad = copy.deepcopy(good)
    bad["runs"][0]["error"]["rmse_all"] = 1e308
    expect("overflow", bad, 2, "runs[0] (a).error.rmse_all: 1e+308 is not a plausible value")
    bad = copy.deepcopy(good)
    bad["runs"][0]["step_ms"]["median"] = "fast"
    expect("string", bad, 2, "runs[0] (a).step_ms.median: expected a number, got a string")
    expect("other_surface", good, 2, "does not match its SHA-256",
           obj=OBJ.replace("v 0 0 1", "v 0 0 2"))
    bad = copy.deepcopy(good)
    del bad["runs"][0]["final_surface_sha256"]
    expect("fewer_vertices", bad, 2, "a/final.obj has 3 vertices, results.json says 4",
           obj=OBJ.replace("v 0 0 1\n", ""))
    bad = copy.deepcopy(good)
    bad["runs"][0]["valid"] = "yes"
    expect("valid_string", bad, 2, "runs[0] (a).valid: expected true or false")

    # The viewer's embedded JSON: no "<" survives, and the label reads back unchanged.
    try:
        import viewer_data
        viewer_data.viewer_assets()
    except (ImportError, OSError):
        viewer_data = None
    if viewer_data is not None:
        import numpy as np
        label = "<!--<script>"
        data = {"scene": "t", "runs": [{"label": label}], "note": "</script>&"}
        head, body = viewer_data.page_parts(data)
        start = body.index('id="dbv-data">') + len('id="dbv-data">')
        payload = body[start:body.index("</script>", start)]
        if "<" in payload or json.loads(payload)["runs"][0]["label"] != label:
            failures.append("viewer payload: %r" % payload[:200])
        del np
    for f in failures:
        print("FAIL " + f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
