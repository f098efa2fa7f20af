#!/usr/bin/env python3
"""What densify's accuracy costs in time: regenerates docs/bench/densify.md.

    python3 docs/bench/densify.py [--bin target/release/nrw-etl] [--quick] [--keep-settings-rows]

For each setting (image size, iterations, window radius, scales, geometric pass) it runs
`nrw-etl densify` on the textured synthetic scene (scenes/textured.toml, whose
ground_truth/depth is the true depth of every pixel) under GNU time, and reports seconds per
view, peak memory, the share of kept depth pixels within 0.5%, 1% and 2% of the true depth
(accuracy) and the share of true-depth pixels that carry a depth within 1% (completeness),
ETH3D's way of counting, their F1, and the fused points.

The peer, in the same run: OpenCV's StereoSGBM, what a CPU user builds by hand today. Each
undistorted view of our workspace is rectified (cv2.stereoRectify) with the registered view a
CPU user would pair it with (the shortest mostly-horizontal baseline of at least 2% of the
view's median depth, within 30 degrees), matched by SGBM (disparity range from the view's SfM
depths), its
disparities turned into depth in the reference view (z-buffered), and fused by COLMAP's
stereo_fusion with the same defaults as ours; scored the same way.

The real scenes (../shared/data): sacre_coeur and sceaux_castle at the default 800 px (and
sacre_coeur with the smaller window):
seconds per view, the median relative difference between the geometric depth at each SfM
observation and the point's depth, and the views ingest keeps afterwards at the paper's
settings (85% empty, 450 px).

Needs numpy, OpenEXR, opencv-python and pycolmap (the test oracles' packages) and `colmap`.
Not a timed test: a report, with the machine's CPU flags.
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

import resource
import time

import cv2
import numpy as np
import OpenEXR
import pycolmap

# COLMAP's own scripts/python/read_write_dense.py, where NRW_COLMAP_SCRIPTS names its folder.
COLMAP_DENSE = None
if os.environ.get("NRW_COLMAP_SCRIPTS"):
    sys.path.insert(0, os.environ["NRW_COLMAP_SCRIPTS"])
    import read_write_dense as COLMAP_DENSE

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def read_bin(path):
    """COLMAP's dense map layout: COLMAP's own read_write_dense.py where NRW_COLMAP_SCRIPTS
    names its folder (as .ci/run sets it), else its reading transcribed (the header's three
    numbers, float32 in Fortran order, transposed and squeezed)."""
    if COLMAP_DENSE:
        return COLMAP_DENSE.read_array(path)
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


def write_bin(path, arr):
    """The inverse of read_bin."""
    arr = arr if arr.ndim == 3 else arr[:, :, None]
    h, w, c = arr.shape
    with open(path, "wb") as f:
        f.write(f"{w}&{h}&{c}&".encode())
        f.write(np.transpose(arr, (1, 0, 2)).astype("<f4").tobytes(order="F"))


def cv_k(cam):
    """An undistorted PINHOLE camera's K in OpenCV's convention (pixel centres at integers)."""
    fx, fy, cx, cy = cam.params
    return np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1.0]])


def sgbm_depth(rec, ref, src, ws):
    """SGBM depth of view `ref` from the pair (ref, src): rectify, match, back to ref's pixels."""
    c1, c2 = rec.cameras[ref.camera_id], rec.cameras[src.camera_id]
    k1, k2 = cv_k(c1), cv_k(c2)
    p1, p2 = ref.cam_from_world(), src.cam_from_world()
    r = p2.rotation.matrix() @ p1.rotation.matrix().T
    t = p2.translation - r @ p1.translation
    size = (c1.width, c1.height)
    zero = np.zeros(5)
    # alpha=1 keeps every pixel of both views: alpha=0 zooms into the region both cover,
    # which for converging views is a small part of the reference.
    r1, r2, q1, q2, q, _, _ = cv2.stereoRectify(k1, zero, k2, zero, size, r, t.reshape(3, 1),
                                                flags=cv2.CALIB_ZERO_DISPARITY, alpha=1)
    if q1[0, 0] <= 0:  # views too far apart to rectify (the rectified focal length flips)
        return None
    load = lambda im: cv2.imread(os.path.join(ws, "images", im.name), cv2.IMREAD_GRAYSCALE)
    # Both views resampled into the common rectified frame, at the reference's size.
    m1 = cv2.initUndistortRectifyMap(k1, zero, r1, q1, size, cv2.CV_32FC1)
    m2 = cv2.initUndistortRectifyMap(k2, zero, r2, q2, size, cv2.CV_32FC1)
    a = cv2.remap(load(ref), *m1, cv2.INTER_LINEAR)
    b = cv2.remap(load(src), *m2, cv2.INTER_LINEAR)
    flip = q2[0, 3] > 0  # the source is left of the reference: mirror both
    if flip:
        a, b = a[:, ::-1].copy(), b[:, ::-1].copy()
    # Disparity range from the view's SfM depths (COLMAP's 1st–99th percentile, widened).
    z = np.array([(p1.rotation.matrix() @ rec.points3D[p.point3D_id].xyz + p1.translation)[2]
                  for p in ref.points2D if p.has_point3D()])
    f_b = abs(q2[0, 3])
    lo, hi = np.percentile(z, 1) * 0.75, np.percentile(z, 99) * 1.25
    dmin = int(np.floor(f_b / hi))
    nd = int(min(384, max(16, np.ceil((f_b / lo - dmin) / 16) * 16)))
    sgbm = cv2.StereoSGBM_create(minDisparity=dmin, numDisparities=nd, blockSize=5,
                                 P1=8 * 25, P2=32 * 25, uniquenessRatio=10,
                                 speckleWindowSize=100, speckleRange=2,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM)
    # SGBM wants its whole disparity range inside the image: pad both on the left (a match
    # that falls in the padding is no match), then cut the padding off.
    pad = dmin + nd
    a, b = (cv2.copyMakeBorder(x, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0) for x in (a, b))
    disp = sgbm.compute(a, b).astype(np.float32)[:, pad:] / 16.0
    if flip:
        disp = disp[:, ::-1]
    valid = disp > dmin
    # Triangulate in the rectified reference frame: Z = f·b / disparity.
    rows, cols = np.nonzero(valid)
    z_rect = f_b / disp[valid]
    f, cx, cy = q1[0, 0], q1[0, 2], q1[1, 2]
    pts = np.stack([(cols - cx) * z_rect / f, (rows - cy) * z_rect / f, z_rect], -1)
    x = pts @ r1  # rectified → reference camera frame (r1ᵀ applied to row vectors)
    depth = np.zeros((c1.height, c1.width), np.float32)
    front = x[:, 2] > 0
    x = x[front]
    u = np.rint(k1[0, 0] * x[:, 0] / x[:, 2] + k1[0, 2]).astype(int)
    v = np.rint(k1[1, 1] * x[:, 1] / x[:, 2] + k1[1, 2]).astype(int)
    inside = (u >= 0) & (v >= 0) & (u < c1.width) & (v < c1.height)
    order = np.argsort(-x[inside, 2])  # nearest written last
    depth[v[inside][order], u[inside][order]] = x[inside, 2][order]
    return depth


def normals_from_depth(depth, k):
    """Per-pixel normals (camera frame, facing the camera) from the depth's neighbours."""
    h, w = depth.shape
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    p = np.stack([(cols - k[0, 2]) / k[0, 0] * depth, (rows - k[1, 2]) / k[1, 1] * depth, depth], -1)
    n = np.cross(np.gradient(p, axis=1), np.gradient(p, axis=0))
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    n[n[..., 2] > 0] *= -1
    n[depth <= 0] = 0
    return n.astype(np.float32)


def sgbm_partner(rec, ref):
    """The registered view a CPU user would pair `ref` with for SGBM: the shortest baseline that
    is mostly horizontal and still at least 2% of the view's median SfM depth, with viewing
    directions within 30 degrees; None when no view qualifies."""
    pose = ref.cam_from_world()
    z = [(pose.rotation.matrix() @ rec.points3D[p.point3D_id].xyz + pose.translation)[2]
         for p in ref.points2D if p.has_point3D()]
    depth = float(np.median(z)) if z else 1.0
    best, best_len = None, np.inf
    for src in rec.images.values():
        if src.image_id == ref.image_id:
            continue
        t = src.cam_from_world()
        r = t.rotation.matrix() @ pose.rotation.matrix().T
        rel = t.translation - r @ pose.translation
        length = float(np.linalg.norm(rel))
        angle = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))
        if abs(rel[0]) >= abs(rel[1]) and angle <= 30 and 0.02 * depth <= length < best_len:
            best, best_len = src, length
    return best


def sgbm_peer(ws, out, min_pixels=5):
    """The SGBM peer over our workspace's views into a copy `out`, fused by COLMAP with
    `min_pixels`; (seconds per view of the stereo loop, peak MB of this process, fused points,
    seconds per view of COLMAP's fusion)."""
    # The model (sparse/*.bin) is copied; our maps and cloud are not.
    shutil.copytree(ws, out, ignore=lambda d, names: [
        n for n in names if n.startswith("fused.ply") or (n.endswith(".bin") and "stereo" in d)])
    rec = pycolmap.Reconstruction(os.path.join(ws, "sparse"))
    by_name = {im.name: im for im in rec.images.values()}
    cfg = open(os.path.join(ws, "stereo/patch-match.cfg")).read().split("\n")
    started = time.perf_counter()
    views = 0
    for name, sources in zip(cfg[0::2], cfg[1::2]):
        if not name:
            continue
        ref = by_name[name]
        pick = sgbm_partner(rec, ref)
        depth = sgbm_depth(rec, ref, pick, ws) if pick else None
        if depth is None:  # no partner, or a disparity range wider than the image
            depth = np.zeros((rec.cameras[ref.camera_id].height, rec.cameras[ref.camera_id].width), np.float32)
        k = cv_k(rec.cameras[ref.camera_id])
        write_bin(os.path.join(out, "stereo/depth_maps", name + ".geometric.bin"), depth)
        write_bin(os.path.join(out, "stereo/normal_maps", name + ".geometric.bin"), normals_from_depth(depth, k))
        views += 1
    secs = time.perf_counter() - started
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    fusion_started = time.perf_counter()
    fused = subprocess.run(["colmap", "stereo_fusion", "--workspace_path", out, "--input_type",
                            "geometric", "--output_path", os.path.join(out, "fused.ply"),
                            "--StereoFusion.min_num_pixels", str(min_pixels)],
                           capture_output=True, text=True)
    fusion = time.perf_counter() - fusion_started
    m = re.search(r"Number of fused points: (\d+)", fused.stdout + fused.stderr)
    if not m:
        print("colmap stereo_fusion said:", (fused.stdout + fused.stderr)[-2000:], file=sys.stderr)
    return secs / max(views, 1), peak, int(m.group(1)) if m else 0, fusion / max(views, 1)


def sfm_median(ws):
    """The median relative difference between each SfM observation's point depth and the
    geometric depth at its pixel, over the workspace's views."""
    rec = pycolmap.Reconstruction(os.path.join(ws, "sparse"))
    rel = []
    for im in rec.images.values():
        p = os.path.join(ws, "stereo/depth_maps", im.name + ".geometric.bin")
        if not os.path.exists(p):
            continue
        d = read_bin(p)
        fx, fy, cx, cy = rec.cameras[im.camera_id].params
        pose = im.cam_from_world()
        for o in im.points2D:
            if not o.has_point3D():
                continue
            x = pose.rotation.matrix() @ rec.points3D[o.point3D_id].xyz + pose.translation
            if x[2] <= 0:
                continue
            u, v = fx * x[0] / x[2] + cx, fy * x[1] / x[2] + cy
            if 0 <= u < d.shape[1] and 0 <= v < d.shape[0] and d[int(v), int(u)] > 0:
                rel.append(abs(d[int(v), int(u)] - x[2]) / x[2])
    return float(np.median(rel)) if rel else float("nan"), len(rel)


def kept_views(binary, scene, cloud, ds):
    """(views ingest keeps at the paper's settings rendering `cloud`, registered views)."""
    r = subprocess.run([binary, "ingest", scene, "--points", cloud, "--out", ds],
                       capture_output=True, text=True)
    kept = re.search(r"(\d+) kept", r.stderr)
    total = re.search(r"(\d+) registered", r.stderr)
    return int(kept.group(1)) if kept else 0, int(total.group(1)) if total else None


def megapixels(ws):
    """The mean size of the workspace's undistorted views, in megapixels."""
    rec = pycolmap.Reconstruction(os.path.join(ws, "sparse"))
    sizes = [rec.cameras[im.camera_id].width * rec.cameras[im.camera_id].height
             for im in rec.images.values()]
    return sum(sizes) / len(sizes) / 1e6


def real_scene(binary, scene, tmp, min_pixels, window, peer, size=800):
    """densify at the defaults (but fusion's min_num_pixels, the window radius and the longer
    side), then ingest at the paper's; with `peer`, the SGBM peer's row over the same workspace
    too."""
    out = os.path.join(tmp, "real_" + os.path.basename(scene))
    secs, rss, views, points = run(binary, scene, out, ["--min-num-pixels", str(min_pixels),
                                                        "--window-radius", str(window),
                                                        "--max-image-size", str(size)])
    median, n = sfm_median(out)
    mp = megapixels(out)
    kept, total = kept_views(binary, scene, os.path.join(out, "fused.ply"), out + "_ds")
    rows = [(f"{size} ({mp:.2f} MP)", str(min_pixels), str(window), secs / max(views, 1),
             rss / 1024, median, n, points, kept, total or views)]
    if peer:
        sgbm = out + "_sgbm"
        spv, mb, pts, _ = sgbm_peer(out, sgbm, min_pixels)
        median, n = sfm_median(sgbm)
        kept, total = kept_views(binary, scene, os.path.join(sgbm, "fused.ply"), sgbm + "_ds")
        rows.append((f"{size} ({mp:.2f} MP)", f"{min_pixels} (COLMAP)", "**peer: SGBM**", spv, mb,
                     median, n, pts, kept, total or views))
    return rows


# Our cheap settings for the equal-time comparison: (longer side, iterations, window radius,
# scales, source views, geometric pass).
FAST = [(60, 1, 2, 1, 4, False), (60, 2, 2, 1, 3, False), (80, 2, 2, 1, 3, False),
        (100, 1, 2, 1, 4, False), (120, 2, 2, 1, 4, False), (120, 1, 2, 1, 8, True),
        (180, 2, 2, 1, 3, True)]
# The peer's image sizes for the same comparison.
PEER_SIZES = [120, 240, 360, 480]


def describe(size, iterations, window, scales, sources, geometric):
    return (f"{size} px, {iterations} it., radius {window}, {scales} scale{'s' if scales > 1 else ''}, "
            f"{sources} sources, geometric {'on' if geometric else 'off'}")


def equal_time(binary, scene, truth, tmp, repeats):
    """Ours at the FAST settings and the SGBM peer at PEER_SIZES, seconds a view the median of
    `repeats` runs (the maps are the same bytes every run, so each is scored once):
    ([(setting, s/view, F1)], [(size, stereo s/view, fusion s/view, F1)])."""
    ours = []
    out = os.path.join(tmp, "fast")
    for size, it, w, sc, src, geo in FAST:
        args = ["--max-image-size", str(size), "--iterations", str(it), "--window-radius", str(w),
                "--scales", str(sc), "--max-sources", str(src)] + ([] if geo else ["--no-geometric"])
        times = []
        for _ in range(repeats):
            secs, _, views, _ = run(binary, scene, out, args)
            times.append(secs / max(views, 1))
        f1 = score(out, truth)[2]
        ours.append((describe(size, it, w, sc, src, geo), float(np.median(times)), f1))
        print(ours[-1], file=sys.stderr)
    peers = []
    for size in PEER_SIZES:
        ws = os.path.join(tmp, f"peer_ws_{size}")
        # Only the workspace's undistorted views and source lists are the peer's input.
        run(binary, scene, ws, ["--max-image-size", str(size), "--iterations", "1",
                                "--window-radius", "1", "--scales", "1", "--no-geometric"])
        stereo, fusion = [], []
        for _ in range(repeats):
            sg = os.path.join(tmp, f"peer_{size}")
            shutil.rmtree(sg, ignore_errors=True)
            spv, _, _, fpv = sgbm_peer(ws, sg)
            stereo.append(spv)
            fusion.append(fpv)
        peers.append((size, float(np.median(stereo)), float(np.median(fusion)), score(sg, truth)[2]))
        print("SGBM", peers[-1], file=sys.stderr)
    return ours, peers


def write_equal_time(f, fast, settings, peers, repeats):
    """The equal-time table: for each peer size, our best F1 in no more seconds a view among
    the cheap settings `fast` and the settings rows `settings`."""
    ours = fast + settings
    f.write("\n## Equal time: the peer's F1 against ours in no more seconds a view\n\n"
            f"Same synthetic scene; seconds a view are the median of {repeats} runs (the settings rows "
            "above: one run each). Ours: the whole "
            "`nrw-etl densify` process (start, undistortion, stereo, fusion). The peer: its stereo "
            "loop alone (as above), and beside it with COLMAP's `stereo_fusion` added (its process, "
            "per view). \"Ours\" is our best F1 among the settings below and the table above whose "
            "seconds a view are at most the peer's stereo loop alone.\n\n")
    f.write("| peer: SGBM at px | peer s / view (stereo) | peer s / view (+ COLMAP fusion) | peer F1 1% "
            "| ours: best F1 1% in no more time | our setting | our s / view | verdict |\n")
    f.write("|---|---|---|---|---|---|---|---|\n")
    for size, spv, fpv, pf1 in peers:
        fits = [o for o in ours if o[1] <= spv]
        if fits:
            name, t, f1 = max(fits, key=lambda o: o[2])
            verdict = "ours better" if f1 > pf1 else "peer better"
            f.write(f"| {size} | {spv:.3f} | {spv + fpv:.3f} | {pf1:.3f} | {f1:.3f} | {name} | {t:.3f} | {verdict} |\n")
        else:
            fastest = min(ours, key=lambda o: o[1])
            f.write(f"| {size} | {spv:.3f} | {spv + fpv:.3f} | {pf1:.3f} | none | (fastest: {fastest[0]}, "
                    f"F1 {fastest[2]:.3f}) | {fastest[1]:.3f} | no setting of ours is this fast |\n")
    f.write("\nOur cheap settings:\n\n| setting | s / view | F1 1% |\n|---|---|---|\n")
    for name, t, f1 in fast:
        f.write(f"| {name} | {t:.3f} | {f1:.3f} |\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default=os.path.join(ROOT, "target/release/nrw-etl"))
    ap.add_argument("--quick", action="store_true", help="fewer settings (a smoke run)")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs/bench/densify.md"))
    ap.add_argument("--keep-settings-rows", action="store_true",
                    help="rerun only the peer and the real scenes, keeping the settings rows "
                         "of an existing report (same binary, same machine)")
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
    kept_rows = []
    if a.keep_settings_rows:
        kept_rows = [l for l in open(a.out).read().split("\n") if l.startswith("| ") and l[2].isdigit()]
        variants = []
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
    # The peer over the base setting's workspace (our undistorted views and their sources).
    base_args = ["--max-image-size", str(base["size"])]
    ours = os.path.join(tmp, "ours")
    run(a.bin, scene, ours, base_args)
    spv, mb, pts, _ = sgbm_peer(ours, os.path.join(tmp, "sgbm"))
    acc, comp, f1 = score(os.path.join(tmp, "sgbm"), truth)
    peer = (spv, mb, acc, comp, f1, pts)
    print("SGBM", f"{spv:.2f} s/view", f"F1 {f1:.3f}", file=sys.stderr)
    repeats = 1 if a.quick else 3
    fast, peers = equal_time(a.bin, scene, truth, tmp, repeats)
    settings = [(describe(v["size"], v["iterations"], v["window"], v["scales"], 8, v["geometric"]), t, f)
             for v, t, _, _, _, f, _ in rows]
    real = []
    data = os.path.join(ROOT, "..", "shared", "data")
    if not a.quick and os.path.isdir(data):
        # 853 px: the longer side at which sacre_coeur's views average 0.5 MP (the target's size).
        for name, m, w, with_peer, size in (("sacre_coeur", 3, 5, True, 800),
                                            ("sacre_coeur", 3, 5, False, 853),
                                            ("sacre_coeur", 5, 5, False, 800),
                                            ("sacre_coeur", 3, 3, False, 800),
                                            ("sceaux_castle", 5, 5, True, 800)):
            for row in real_scene(a.bin, os.path.join(data, name), tmp, m, w, with_peer, size):
                real.append((name, *row))
                print(real[-1], file=sys.stderr)
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
        for line in kept_rows:
            f.write(line + "\n")
        for v, spv, mb, acc, comp, f1, pts in rows:
            f.write(f"| {v['size']} | {v['iterations']} | {v['window']} | {v['scales']} | "
                    f"{'on' if v['geometric'] else 'off'} | {spv:.2f} | {mb:.0f} | {acc[0.005]:.3f} | "
                    f"{acc[0.01]:.3f} | {acc[0.02]:.3f} | {comp:.3f} | {f1:.3f} | {pts} |\n")
        spv, mb, acc, comp, f1, pts = peer
        f.write(f"| **peer: OpenCV StereoSGBM** ({cv2.__version__}), {base['size']} px, one rectified pair a view, "
                f"fused by COLMAP | | | | | {spv:.2f} | {mb:.0f} | {acc[0.005]:.3f} | {acc[0.01]:.3f} | "
                f"{acc[0.02]:.3f} | {comp:.3f} | {f1:.3f} | {pts} |\n")
        f.write("\nThe peer's seconds are its Python loop (rectify, SGBM, back to the view's pixels, one "
                "thread per view as OpenCV runs it); its peak memory is the script's. Our first row and the "
                "peer's share their undistorted views and source lists.\n")
        write_equal_time(f, fast, settings, peers, repeats)
        if real:
            f.write("\n## Real scenes (../shared/data), default settings (800 px) and 0.5 MP\n\n"
                    "SfM: median relative difference between the geometric depth at each SfM observation's "
                    "pixel and the point's depth. Kept: views `ingest --points dense/fused.ply` keeps at the "
                    "paper's settings (from the sparse model: 0 of 10 on sacre_coeur). The peer rows: "
                    "SGBM over the row above's workspace (its undistorted views, one rectified pair a "
                    "view, as above), fused by COLMAP with the same min_num_pixels, measured the same "
                    "way.\n\n")
            f.write("| scene | longer side px (mean view) | fusion min_num_pixels | window radius | s / view | peak MB | SfM median | SfM observations | fused points | kept views |\n")
            f.write("|---|---|---|---|---|---|---|---|---|---|\n")
            for name, size, m, w, spv, mb, med, n, pts, kept, total in real:
                f.write(f"| {name} | {size} | {m} | {w} | {spv:.2f} | {mb:.0f} | {med:.5f} | {n} | {pts} | {kept} of {total} |\n")
    shutil.rmtree(tmp)
    print(a.out)


if __name__ == "__main__":
    main()
