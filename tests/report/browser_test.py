#!/usr/bin/env python3
"""The report's 3D viewer in a real browser (headless Chromium, WebGL through SwiftShader).

usage: browser_test.py DEFORMBENCH_EXE WORK_DIR

Makes a small synthetic results folder, runs `deformbench report` on it, loads the report in
headless Chromium and checks: the viewer says it is ready and recorded no JavaScript error, no
console message reports an error, the viewer area of a screenshot is not blank, the pictures at
the first and the last frame (URL hash frame=K, what the time slider sets) differ, the largest
distance to the reference the viewer computes from its decoded surfaces matches results.json
within 1%, the colour scale switch (#scale=shared|panel) takes effect, and a page
with broken viewer data is reported as an error (so the checks can fail).
Exit 77 (ctest: skipped) when Chromium or three.js is absent.
"""
import os
import re
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "harness", "scripts"))


def chromium():
    for name in (os.environ.get("DEFORM_CHROMIUM"), "chromium", "chromium-browser"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def browse(exe, work, url, extra):
    profile = os.path.join(work, "profile")
    shutil.rmtree(profile, ignore_errors=True)
    cmd = [exe, "--headless", "--no-sandbox", "--use-angle=swiftshader",
           "--enable-unsafe-swiftshader", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run",
           "--user-data-dir=" + profile, "--enable-logging=stderr", "--v=0",
           "--virtual-time-budget=5000", "--window-size=1200,900"] + extra + [url]
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=120)
    console = [l for l in p.stderr.splitlines() if ":CONSOLE" in l]
    return p.returncode, p.stdout, console


def main():
    if len(sys.argv) != 3:
        print(__doc__)
        return 2
    program, work = sys.argv[1], sys.argv[2]
    exe = chromium()
    if not exe:
        print("SKIP: chromium not found (Debian package chromium; scripts/install-deps.sh)")
        return 77
    import viewer_data
    try:
        viewer_data.viewer_assets()
    except OSError as e:
        print("SKIP: %s" % e)
        return 77
    from PIL import Image

    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    run = os.path.join(work, "run")
    subprocess.run([sys.executable, os.path.join(HERE, "synthetic_results.py"), run,
                    "--models", "2", "--frames", "6"], check=True, stdout=subprocess.DEVNULL)
    rep = subprocess.run([program, "report", run], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    failures = []
    if rep.returncode != 0 or not re.search(r"report\.html \(.* MB", rep.stdout):
        print("deformbench report failed (%d): %s %s" % (rep.returncode, rep.stdout, rep.stderr))
        return 1
    url = "file://" + os.path.join(run, "report.html")

    code, dom, console = browse(exe, work, url + "#frame=last", ["--dump-dom"])
    body = (re.search(r"<body[^>]*>", dom) or re.search("", "")).group(0)
    status = re.search(r'data-viewer-status="([^"]*)"', body)
    stage = re.search(r'data-viewer-stage="(\d+),(\d+),(\d+),(\d+)"', body)
    if code != 0 or not status or status.group(1) != "ready":
        failures.append("viewer not ready (exit %d, status %s)"
                        % (code, status.group(1) if status else "absent"))
    if "data-viewer-errors" in body:
        failures.append("the viewer recorded errors: %s"
                        % re.findall(r'class="dbv-errors">([^<]*)', dom))
    bad = [l for l in console if re.search(r"error|uncaught", l, re.I)]
    if bad:
        failures.append("console errors: %s" % bad)
    if not stage:
        failures.append("no stage rectangle in the DOM")
        print("\n".join(failures))
        return 1
    x, y, w, h = (int(v) for v in stage.groups())
    # The distances the viewer computed from its decoded surfaces against the full-precision
    # maxima of the last frame in results.json.
    import json
    with open(os.path.join(run, "results.json")) as f:
        want = [1e3 * r["error"]["max"] for r in json.load(f)["runs"] if r["role"] == "model"]
    got = [float(v) for v in re.findall(r'data-frame-max-mm="([0-9.e+-]+)"', dom)]
    if len(got) != len(want) or any(abs(a - b) > 0.01 * b for a, b in zip(got, want)):
        failures.append("viewer's last-frame maxima %s mm, results.json %s mm" % (got, want))

    # The colour scale: shared by every panel or each panel its own (#scale=, the switch), the
    # latter named in each model's box.
    for scale in ("shared", "panel"):
        _, dom_s, _ = browse(exe, work, url + "#frame=last&scale=" + scale, ["--dump-dom"])
        named = len(re.findall(r"colour scale 0 to [^'<]+\(this panel\)", dom_s))
        if 'data-viewer-scale="%s"' % scale not in dom_s or named != (
                len(want) if scale == "panel" else 0):
            failures.append("scale=%s: not applied (%d panel scales named)" % (scale, named))

    pics = []
    for frame in ("0", "last"):
        png = os.path.join(work, "frame_%s.png" % frame)
        browse(exe, work, url + "#frame=" + frame, ["--screenshot=" + png])
        img = Image.open(png).convert("RGB").crop((x, y, x + w, min(y + h, 900)))
        pics.append(img)
    a, b = pics
    px_a, px_b = list(a.getdata()), list(b.getdata())
    background = {(0xf4, 0xf4, 0xf4), (0xff, 0xff, 0xff)}
    drawn = sum(1 for p in px_a if p not in background) / len(px_a)
    changed = sum(1 for p, q in zip(px_a, px_b) if p != q) / len(px_a)
    print("viewer area %dx%d: %.1f%% drawn at frame 0, %.1f%% of pixels differ at the last frame"
          % (w, h, 100 * drawn, 100 * changed))
    if drawn < 0.05:
        failures.append("the viewer area is blank (%.2f%% drawn)" % (100 * drawn))
    if changed < 0.005:
        failures.append("moving to the last frame did not change the picture")

    # Negative control: broken data must show as an error.
    with open(os.path.join(run, "report.html")) as f:
        page = f.read()
    broken = re.sub(r'(<script type="application/json" id="dbv-data">)[^<]*', r'\1{"runs": 1}',
                    page, count=1)
    with open(os.path.join(run, "broken.html"), "w") as f:
        f.write(broken)
    _, dom2, _ = browse(exe, work, "file://" + os.path.join(run, "broken.html"), ["--dump-dom"])
    body2 = (re.search(r"<body[^>]*>", dom2) or re.search("", "")).group(0)
    if 'data-viewer-status="error"' not in body2:
        failures.append("broken viewer data was not reported as an error")
    for f in failures:
        print("FAIL: " + f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
