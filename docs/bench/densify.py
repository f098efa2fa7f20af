#!/usr/bin/env python3
"""What densify's accuracy costs in time: regenerates docs/bench/densify.md.

    python3 docs/bench/densify.py [--bin target/release/nrw-etl] [--quick]

For each setting (image size, iterations, window radius, scales, geometric pass) it runs
`nrw-etl densify` on the textured synthetic scene (scenes/textured.toml, whose
ground_truth/depth is the true depth of every pixel) under GNU time, and reports seconds per
view, peak memory, the share of kept depth pixels within 0.5%, 1% and 2% of the true depth
(accuracy) and the share of true-depth pixels that carry a depth within 1% (completeness),
ETH3D's way of counting, their F1, and the fused points. Needs numpy and OpenEXR (the test
oracles' packages). Not a timed test: a report, with the machine's CPU flags.
"""

import argparse
import glob
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile

import numpy as np
import OpenEXR

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def read_bin(path):
    """COLMAP's dense map layout, as scripts/python/read_write_dense.py reads it."""
    with open(path, "rb") as f:
        data = f.read()
    w, h, c, rest = data.split(b"&", 3)
    arr = np.frombuffer(rest, dtype="<f4").reshape((int(w), int(h), int(c)), order="F")
    return np.transpose(arr, (1, 0, 2)).squeeze()


def resize_nearest(t, shape):
    ys = (np.arange(shape[0]) * t.shape[0] // shape[0]).clip(0, t.shape[0] - 1)
    xs = (np.arange(shape[1]) * t.shape[1] // shape[1]).clip(0, t.shape[1] - 1)
    return t[ys][:, xs]


def score(ws, truth_dir):
    within = {0.005: 0, 0.01: 0, 0.02: 0}
    kept, truth_px, complete = 0, 0, 0
    for p in sorted(glob.glob(os.path.join(ws, "stereo/depth_maps/*.geometric.bin"))):
        name = os.path.basename(p).split(".")[0]
        d = read_bin(p)
        t = list(OpenEXR.File(os.path.join(truth_dir, name + ".exr")).channels().values())[0]
        t = resize_nearest(t.pixels.astype(np.float64), d.shape)
        m = (d > 0) & (t > 0)
        rel = np.abs(d[m] - t[m]) / t[m]
        kept += m.sum()
        for k in within:
            within[k] += (rel <= k).sum()
        truth_px += (t > 0).sum()
        complete += (rel <= 0.01).sum()
    acc = {k: v / max(kept, 1) for k, v in within.items()}
    comp = complete / max(truth_px, 1)
    f1 = 2 * acc[0.01] * comp / max(acc[0.01] + comp, 1e-12)
    return acc, comp, f1


def run(binary, scene, out, args):
    cmd = ["/usr/bin/time", "-v", binary, "densify", scene, "-q", "--overwrite", "--out", out] + args
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    clock = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)", r.stderr).group(1)
    secs = 0.0
    for part in clock.split(":"):
        secs = secs * 60 + float(part)
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr).group(1))
    views = int(re.search(r"densified (\d+) of", r.stderr).group(1))
    points = int(re.search(r"fused (\d+) points", r.stderr).group(1))
    return secs, rss, views, points


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default=os.path.join(ROOT, "target/release/nrw-etl"))
    ap.add_argument("--quick", action="store_true", help="fewer settings (a smoke run)")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs/bench/densify.md"))
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="nrw-densify-bench-")
    scene = os.path.join(tmp, "scene")
    subprocess.run([a.bin, "synth", os.path.join(ROOT, "scenes/textured.toml"), "--out", scene],
                   check=True, capture_output=True)
    shutil.rmtree(os.path.join(scene, "dense"))
    truth = os.path.join(scene, "ground_truth/depth")
    base = {"size": 360, "iterations": 5, "window": 5, "scales": 2, "geometric": True}
    variants = [dict(base)]
    sizes = [240] if a.quick else [240, 480]
    for s in sizes:
        variants.append(dict(base, size=s))
    for it in ([3] if a.quick else [3, 8]):
        variants.append(dict(base, iterations=it))
    variants.append(dict(base, window=3))
    variants.append(dict(base, scales=1))
    variants.append(dict(base, geometric=False))
    rows = []
    for v in variants:
        args = ["--max-image-size", str(v["size"]), "--iterations", str(v["iterations"]),
                "--window-radius", str(v["window"]), "--scales", str(v["scales"])]
        if not v["geometric"]:
            args.append("--no-geometric")
        out = os.path.join(tmp, "ws")
        secs, rss, views, points = run(a.bin, scene, out, args)
        acc, comp, f1 = score(out, truth)
        rows.append((v, secs / max(views, 1), rss / 1024, acc, comp, f1, points))
        print(v, f"{secs / max(views, 1):.2f} s/view", f"F1 {f1:.3f}", file=sys.stderr)
    flags = [f for f in ("avx512f", "avx2", "fma") if f in open("/proc/cpuinfo").read().split()]
    with open(a.out, "w") as f:
        f.write("# densify: what accuracy costs in time\n\n")
        f.write("Made by `python3 docs/bench/densify.py` (scenes/textured.toml, 10 PINHOLE photos, "
                "true depth per pixel). Seconds per view and peak memory of the whole "
                "`nrw-etl densify` process (undistortion, photometric and geometric passes, fusion) "
                "under GNU time; accuracy: kept geometric depths within 0.5 / 1 / 2 % of the true depth; "
                "completeness: true-depth pixels with a depth within 1 %; F1 of the two at 1 %.\n\n")
        f.write(f"Machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}, "
                f"CPU flags {', '.join(flags)}; binary {os.path.relpath(a.bin, ROOT)}.\n\n")
        f.write("| longer side px | iterations | window radius | scales | geometric | s / view | peak MB "
                "| acc 0.5% | acc 1% | acc 2% | completeness 1% | F1 1% | fused points |\n")
        f.write("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n")
        for v, spv, mb, acc, comp, f1, pts in rows:
            f.write(f"| {v['size']} | {v['iterations']} | {v['window']} | {v['scales']} | "
                    f"{'on' if v['geometric'] else 'off'} | {spv:.2f} | {mb:.0f} | {acc[0.005]:.3f} | "
                    f"{acc[0.01]:.3f} | {acc[0.02]:.3f} | {comp:.3f} | {f1:.3f} | {pts} |\n")
        f.write("\nNot in this table yet (issue 46): the OpenCV StereoSGBM peer run in the same "
                "script, and the real scenes' agreement with their SfM points (tests/densify.rs "
                "measures sacre_coeur's).\n")
    shutil.rmtree(tmp)
    print(a.out)


if __name__ == "__main__":
    main()
