#!/usr/bin/env python3
"""densify beside OpenMVS, in one run: regenerates docs/bench/densify_openmvs.md.

    NRW_OPENMVS_BIN=DIR python3 docs/bench/densify_openmvs.py [--bin target/release/nrw-etl]
        [--threads 2] [--quick] [--parts presets,sizes,real] [--pixel-samples 3]

Three parts: each preset (`fast`, `default`, `thorough`) and OpenMVS on scenes/textured.toml
and scenes/wild.toml at 360 px and on scenes/hard.toml (small and far photos, night, haze) at
816 px; the default and OpenMVS on one scene of wild's photographers with photos of about 1 MP,
capped at 632, 816 and 1155 px (0.3, 0.5 and 1 MP); the real scenes. Synthetic photos are
rendered with 3 × 3 rays a pixel (`pixel_samples`; 1 aliases the ground's texture). Views a
map: how many source views each tool matched a depth map with (ours: patch-match.cfg;
OpenMVS: its log).

DIR holds OpenMVS's InterfaceCOLMAP and DensifyPointCloud, as ../shared/tools/build-openmvs.sh
builds them (its version is read from `DensifyPointCloud --help`). Both tools run on the same
undistorted workspace — the photos and PINHOLE model `nrw-etl densify` writes (COLMAP's
`image_undistorter` output), copied without our depth maps so OpenMVS cannot reuse them — at
the same image size, each alone on the same `--threads` cores, under GNU time (seconds per
view, peak resident memory; OpenMVS's two steps summed and maxed). OpenMVS runs as a CPU user
runs it: `InterfaceCOLMAP -i WS -o scene.mvs --image-folder WS/images`, then
`DensifyPointCloud scene.mvs --resolution-level 0 --max-threads N`.

Synthetic scenes (scenes/textured.toml, scenes/wild.toml; the truth is their dense/fused.ply
made denser, and ground_truth/depth per photo), ETH3D's way at 0.25%, 0.5% and 1% of the
median true depth: accuracy = share of fused points within the tolerance of a true point;
completeness = share of the true points that at least two photos see (a point is seen where
its depth equals the true depth at its pixel of the original photo within 1%) with a fused
point within the tolerance; F1 of the two. Again over the surfaces off the ground (true points
above z = 0.05 m; fused points whose nearest true point is one).

Real scenes (../shared/data; mean view 0.5 MP): the SfM agreement (share of the SfM points of
tracks of two or more with a fused point within 1% of their depth in their first observing
view), and the views `nrw-etl ingest --points CLOUD` keeps at the paper's settings.

Needs numpy, scipy, plyfile, OpenEXR and pycolmap, GNU time, and OpenMVS.
Not a timed test: a report, with the machine's CPU flags.
"""

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile

import numpy as np
import OpenEXR
import pycolmap
from plyfile import PlyData, PlyElement
from scipy.spatial import cKDTree

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TOLERANCES = (0.0025, 0.005, 0.01)
OFF_GROUND_Z = 0.05
PROJECTION_PHOTOS = 7711


def timed(cmd, cwd=None):
    """Run under GNU time: (seconds, peak MB, stderr)."""
    r = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True, cwd=cwd)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stdout[-2000:]}\n{r.stderr[-4000:]}")
    clock = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)", r.stderr).group(1)
    secs = 0.0
    for part in clock.split(":"):
        secs = secs * 60 + float(part)
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr).group(1))
    return secs, rss / 1024, r.stderr


def read_xyz(path):
    v = PlyData.read(path)["vertex"]
    return np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float64)


def write_cloud(path, xyz, rgb, normals):
    """A PLY in COLMAP's fused.ply vertex layout, which ingest reads."""
    dt = [("x", "f4"), ("y", "f4"), ("z", "f4"), ("nx", "f4"), ("ny", "f4"), ("nz", "f4"),
          ("red", "u1"), ("green", "u1"), ("blue", "u1")]
    v = np.empty(len(xyz), dtype=dt)
    for i, k in enumerate("xyz"):
        v[k] = xyz[:, i]
    for i, k in enumerate(("nx", "ny", "nz")):
        v[k] = normals[:, i]
    for i, k in enumerate(("red", "green", "blue")):
        v[k] = rgb[:, i]
    PlyData([PlyElement.describe(v, "vertex")], byte_order="<").write(path)


def ours(binary, scene, ws, size, threads, preset="default"):
    flags = ["--max-image-size", str(size), "--preset", preset]
    secs, mb, _ = timed(["env", f"RAYON_NUM_THREADS={threads}", binary, "densify", scene, "-q",
                         "--overwrite", "--out", ws] + flags)
    return secs, mb, os.path.join(ws, "fused.ply")


def openmvs(bindir, ws, work, threads):
    """OpenMVS on a copy of the workspace's photos and model."""
    src = os.path.join(work, "ws")
    os.makedirs(src)
    shutil.copytree(os.path.join(ws, "images"), os.path.join(src, "images"))
    shutil.copytree(os.path.join(ws, "sparse"), os.path.join(src, "sparse"))
    mvs = os.path.join(work, "scene.mvs")
    s1, m1, _ = timed([os.path.join(bindir, "InterfaceCOLMAP"), "-i", src, "-o", mvs,
                       "--image-folder", os.path.join(src, "images")], cwd=work)
    # OpenMVS lowers its own priority by default (--process-priority -1): at normal priority,
    # like ours, anything else on the machine takes from both alike.
    s2, m2, _ = timed([os.path.join(bindir, "DensifyPointCloud"), mvs, "--resolution-level", "0",
                       "--max-threads", str(threads), "--process-priority", "0", "-w", work],
                      cwd=work)
    return s1 + s2, max(m1, m2), os.path.join(work, "scene_dense.ply")


def openmvs_views(work):
    """The mean number of source views OpenMVS estimated a depth map with, from its log
    (`Depth-map for image N estimated using K images`, or `with image M estimated` for one),
    or None."""
    counts = []
    for name in os.listdir(work):
        if name.endswith(".log"):
            text = open(os.path.join(work, name), errors="replace").read()
            for many, one in re.findall(
                    r"Depth-map for image\s+\d+ (?:estimated using\s+(\d+) images|(with image))", text):
                counts.append(int(many) if many else 1)
    return float(np.mean(counts)) if counts else None


def openmvs_version(bindir):
    """The version `DensifyPointCloud --help` prints (run in a scratch folder: it leaves a
    log file where it runs)."""
    with tempfile.TemporaryDirectory() as scratch:
        r = subprocess.run([os.path.join(bindir, "DensifyPointCloud"), "--help"],
                           capture_output=True, text=True, cwd=scratch)
    m = re.search(r"OpenMVS[^\n]*?v?(\d+\.\d+\.\d+)", r.stdout + r.stderr)
    return m.group(1) if m else "unknown version"


def exr_depth(path):
    return list(OpenEXR.File(path).channels().values())[0].pixels.astype(np.float64)


def seen_by_two(scene, truth):
    """The true points at least two photos see, and the median true depth."""
    rec = pycolmap.Reconstruction(os.path.join(scene, "sparse/0"))
    counts = np.zeros(len(truth), dtype=np.int32)
    depths = []
    for im in rec.images.values():
        cam = rec.cameras[im.camera_id]
        t = exr_depth(os.path.join(scene, "ground_truth/depth", os.path.splitext(im.name)[0] + ".exr"))
        depths.append(t[t > 0])
        pose = im.cam_from_world()
        pc = truth @ pose.rotation.matrix().T + pose.translation
        front = pc[:, 2] > 0
        uv = np.full((len(truth), 2), -1.0)
        uv[front] = np.nan_to_num(np.array(cam.img_from_cam(pc[front])), nan=-1.0, posinf=-1.0, neginf=-1.0)
        sx, sy = t.shape[1] / cam.width, t.shape[0] / cam.height
        uv = np.clip(uv, -1.0, 1e9)
        col = np.floor(uv[:, 0] * sx).astype(np.int64)
        row = np.floor(uv[:, 1] * sy).astype(np.int64)
        ok = front & (col >= 0) & (row >= 0) & (col < t.shape[1]) & (row < t.shape[0])
        tz = np.zeros(len(truth))
        tz[ok] = t[row[ok], col[ok]]
        seen = ok & (tz > 0) & (np.abs(pc[:, 2] - tz) <= 0.01 * np.maximum(tz, 1e-12))
        counts += seen
    return counts >= 2, float(np.median(np.concatenate(depths)))


def scores(fused, truth, two, median):
    """(accuracy, completeness, F1) at each tolerance, over everything and off the ground."""
    t_tree, f_tree = cKDTree(truth), cKDTree(fused)
    off = truth[:, 2] > OFF_GROUND_Z
    d_acc, nearest = t_tree.query(fused)
    fused_off = off[nearest]
    d_comp, _ = f_tree.query(truth[two])
    two_off = off[two]
    out = {}
    for tol in TOLERANCES:
        r = tol * median
        for part, fm, tm in (("all", np.ones(len(fused), bool), np.ones(two.sum(), bool)),
                             ("off", fused_off, two_off)):
            a = float((d_acc[fm] <= r).mean()) if fm.any() else 0.0
            c = float((d_comp[tm] <= r).mean()) if tm.any() else 0.0
            out[(tol, part)] = (a, c, 2 * a * c / max(a + c, 1e-12))
    return out


def make_scene(args, spec_path, name, work, shorter=None, count=None):
    """A synthetic scene from a spec, its truth made denser (3·10⁶ points); `shorter` sets
    the photos' shorter side, `count` their number."""
    spec = open(spec_path).read()
    spec = re.sub(r"points = \d+", "points = 3000000", spec)
    if shorter:
        spec = re.sub(r"min_size = \d+", f"min_size = {shorter}", spec)
        spec = re.sub(r"max_size = \d+", f"max_size = {shorter + 20}", spec)
    if "pixel_samples" not in spec:
        spec = spec.replace("[cameras]\n", f"[cameras]\npixel_samples = {args.pixel_samples}\n")
    if count or args.quick:
        spec = re.sub(r"count = \d+", f"count = {args.quick_photos if args.quick else count}", spec)
    d = os.path.join(work, name)
    os.makedirs(d)
    with open(os.path.join(d, "spec.toml"), "w") as f:
        f.write(spec)
    scene = os.path.join(d, "scene")
    subprocess.run([args.bin, "synth", os.path.join(d, "spec.toml"), "--out", scene], check=True,
                   capture_output=True)
    truth = read_xyz(os.path.join(scene, "dense/fused.ply"))
    shutil.move(os.path.join(scene, "dense"), os.path.join(scene, "dense_truth"))
    return d, scene, truth


def mean_mp(ws):
    """The mean size of the undistorted views a workspace holds, in megapixels."""
    cams = pycolmap.Reconstruction(os.path.join(ws, "sparse")).cameras.values()
    return float(np.mean([c.width * c.height for c in cams])) / 1e6


def our_views(ws):
    """The mean number of source views our depth maps were matched with (patch-match.cfg:
    a view's name, then its sources on the next line)."""
    lines = open(os.path.join(ws, "stereo/patch-match.cfg")).read().splitlines()
    counts = [len([n for n in src.split(",") if n.strip()]) for src in lines[1::2]]
    return float(np.mean(counts)) if counts else None


def synthetic(args, made, tag, size, presets):
    """Our presets and OpenMVS on one synthetic scene (`made`: make_scene's) at one size,
    scored against the truth."""
    d, scene, truth = made
    views = len(pycolmap.Reconstruction(os.path.join(scene, "sparse/0")).images)
    two, median = seen_by_two(scene, truth)
    rows = []
    ws = None
    for preset in presets:
        ws = os.path.join(d, f"ours_{preset}_{size}")
        s, mb, cloud = ours(args.bin, scene, ws, size, args.threads, preset)
        label = "nrw-etl densify" + ("" if preset == "default" else f" --preset {preset}")
        rows.append((label, s / views, mb, scores(read_xyz(cloud), truth, two, median),
                     len(read_xyz(cloud)), our_views(ws)))
    work_mvs = os.path.join(d, f"openmvs_{size}")
    s, mb, cloud = openmvs(args.openmvs, ws, work_mvs, args.threads)
    rows.append((f"OpenMVS {args.openmvs_version}", s / views, mb,
                 scores(read_xyz(cloud), truth, two, median), len(read_xyz(cloud)),
                 openmvs_views(work_mvs)))
    return {"name": tag, "views": views, "size": size, "mp": mean_mp(ws), "two": int(two.sum()),
            "two_off": int((two & (truth[:, 2] > OFF_GROUND_Z)).sum()), "median": median,
            "rows": rows}


def sfm_agreement(model_dir, cloud):
    rec = pycolmap.Reconstruction(model_dir)
    tree = cKDTree(cloud)
    hit, n = 0, 0
    for p in rec.points3D.values():
        if p.track.length() < 2:
            continue
        im = rec.images[p.track.elements[0].image_id]
        z = (im.cam_from_world() * p.xyz)[2]
        if z <= 0:
            continue
        n += 1
        hit += tree.query(p.xyz)[0] <= 0.01 * z
    return hit / max(n, 1), n


def kept_views(binary, scene, cloud, out):
    r = subprocess.run([binary, "ingest", scene, "--points", cloud, "--out", out],
                       capture_output=True, text=True)
    m = re.search(r"(\d+) registered, (\d+) kept", r.stderr)
    if not m:
        sys.exit(f"ingest of {cloud} said nothing of kept views:\n{r.stderr}")
    return int(m.group(2)), int(m.group(1))


def real(args, name, size, work):
    scene = os.path.join(ROOT, "..", "shared", "data", name)
    d = os.path.join(work, name)
    os.makedirs(d)
    views = len(pycolmap.Reconstruction(os.path.join(scene, "sparse/0")).images)
    rows = []
    ws = os.path.join(d, "ours")
    s, mb, cloud = ours(args.bin, scene, ws, size, args.threads)
    model = os.path.join(ws, "sparse")
    mp = np.mean([c.width * c.height for c in pycolmap.Reconstruction(model).cameras.values()]) / 1e6
    xyz = read_xyz(cloud)
    agree, n = sfm_agreement(os.path.join(scene, "sparse/0"), xyz)
    kept = kept_views(args.bin, scene, cloud, os.path.join(d, "ds_ours"))
    rows.append(("nrw-etl densify", s / views, mb, agree, n, len(xyz), kept))
    s, mb, cloud = openmvs(args.openmvs, ws, os.path.join(d, "openmvs"), args.threads)
    v = PlyData.read(cloud)["vertex"]
    xyz = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float64)
    names = v.data.dtype.names
    normals = (np.stack([v["nx"], v["ny"], v["nz"]], 1) if "nx" in names
               else np.zeros_like(xyz))
    rgb = np.stack([v["red"], v["green"], v["blue"]], 1)
    plain = os.path.join(d, "openmvs_fused.ply")
    write_cloud(plain, xyz, rgb, normals)
    agree, n = sfm_agreement(os.path.join(scene, "sparse/0"), xyz)
    kept = kept_views(args.bin, scene, plain, os.path.join(d, "ds_openmvs"))
    rows.append((f"OpenMVS {args.openmvs_version}", s / views, mb, agree, n, len(xyz), kept))
    return {"name": name, "size": size, "mp": mp, "views": views, "rows": rows}


def cpu_flags():
    flags = open("/proc/cpuinfo").read().split("flags")[1].split("\n")[0].split()
    return ", ".join(f for f in ("avx512f", "avx2", "fma") if f in flags)


def scene_table(s):
    """One synthetic scene's rows: time, memory, views a map, and F1 (accuracy / completeness)
    at each tolerance, over everything and off the ground."""
    lines = [
        f"### {s['name']} ({s['views']} photos, longer side {s['size']} px, mean {s['mp']:.2f} MP; "
        f"{s['two']} true points two photos see, {s['two_off']} of them off the ground; median "
        f"depth {s['median']:.2f})",
        "",
        "| tool | s / view | peak MB | views a map | fused points | "
        + " | ".join(f"F1 {t * 100:g}% (acc / comp)" for t in TOLERANCES)
        + " | " + " | ".join(f"off ground F1 {t * 100:g}% (acc / comp)" for t in TOLERANCES)
        + " |",
        "|---|---|---|---|---|" + "---|" * (2 * len(TOLERANCES)),
    ]
    for tool, spv, mb, sc, n, nv in s["rows"]:
        cells = []
        for part in ("all", "off"):
            for t in TOLERANCES:
                a, c, f = sc[(t, part)]
                cells.append(f"**{f:.3f}** ({a:.3f} / {c:.3f})")
        views = f"{nv:.1f}" if nv is not None else "?"
        lines.append(f"| {tool} | {spv:.2f} | {mb:.0f} | {views} | {n} | " + " | ".join(cells) + " |")
    return lines + [""]


def size_table(sized):
    """Seconds a view of the default preset and OpenMVS at each size, with their ratio and
    the cost a pixel."""
    lines = [
        "| longer side px | mean MP | ours s / view (peak MB) | OpenMVS s / view (peak MB) | ratio | "
        "ours µs / px | OpenMVS µs / px | completeness 1% ours / OpenMVS | F1 1% ours / OpenMVS |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in sized:
        ours_row = next(r for r in s["rows"] if r[0] == "nrw-etl densify")
        mvs = s["rows"][-1]
        us = [r[1] / (s["mp"] * 1e6) * 1e6 for r in (ours_row, mvs)]
        comp = [r[3][(0.01, "all")][1] for r in (ours_row, mvs)]
        f1 = [r[3][(0.01, "all")][2] for r in (ours_row, mvs)]
        lines.append(f"| {s['size']} | {s['mp']:.2f} | {ours_row[1]:.2f} ({ours_row[2]:.0f}) | "
                     f"{mvs[1]:.2f} ({mvs[2]:.0f}) | **{ours_row[1] / mvs[1]:.2f}×** | {us[0]:.1f} | "
                     f"{us[1]:.1f} | {comp[0]:.3f} / {comp[1]:.3f} | {f1[0]:.3f} / {f1[1]:.3f} |")
    return lines + [""]


def report(args, synth, sized, reals):
    lines = [
        "# densify beside OpenMVS",
        "",
        f"Made by `NRW_OPENMVS_BIN=DIR python3 docs/bench/densify_openmvs.py` (OpenMVS "
        f"{args.openmvs_version}, built by ../shared/tools/build-openmvs.sh). Both on the same "
        "undistorted workspace (our `densify`'s photos and PINHOLE model, which are COLMAP's "
        f"`image_undistorter` output), at the same size, each alone on {args.threads} threads; "
        "seconds per view and peak memory of the whole process under GNU time (OpenMVS: "
        "`InterfaceCOLMAP` + `DensifyPointCloud --resolution-level 0`). Views a map: the mean "
        "number of source views a depth map was matched with (ours: `stereo/patch-match.cfg`; "
        "OpenMVS: its log's `estimated using K images`).",
        "",
        f"Machine: {os.cpu_count()} cores, CPU flags {cpu_flags()}; binary {args.bin}.",
        "",
        "## Synthetic scenes against the truth (ETH3D's counting), each preset",
        "",
        "Tolerance: a share of the median true depth. Accuracy: fused points within it of a true "
        "point (the truth: the scene's surface sampled with 3·10⁶ points). Completeness: of "
        "**every true point at least two photos see** (its depth equals the true depth at its "
        "pixel of the original photo within 1%), the share with a fused point within it. "
        f"Off the ground: true points above z = {OFF_GROUND_Z} m (façade, columns, steps) and the "
        "fused points whose nearest true point is one. Scenes: scenes/textured.toml and "
        "scenes/wild.toml (360 px), scenes/hard.toml (no test uses it: small and far photos, "
        "night and haze, about 0.5 MP).",
        "",
    ]
    for s in synth:
        lines += scene_table(s)
    if sized:
        lines += [
            "## Time at every size (scenes/wild.toml's photographers, photos of about 1 MP, "
            "capped at each size)",
            "",
            "Seconds a view of the default preset and of OpenMVS on the same scene at each cap of "
            "the longer side; µs / px: seconds a view over the mean pixels a view. The scenes' "
            "full rows follow the summary.",
            "",
        ] + size_table(sized)
        for s in sized:
            lines += scene_table(s)
    lines += [
        "## Real scenes (../shared/data), mean view about 0.5 MP",
        "",
        "SfM agreement: of the SfM points with tracks of two or more, the share with a fused point "
        "within 1% of their depth (in their first observing view). Kept: the views "
        "`nrw-etl ingest --points CLOUD` keeps at the paper's settings (85% empty, 450 px).",
        "",
        "| scene | longer side px (mean MP) | tool | s / view | peak MB | SfM agreement | fused points | kept views |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in reals:
        for tool, spv, mb, agree, n, pts, (kept, reg) in r["rows"]:
            lines.append(f"| {r['name']} | {r['size']} ({r['mp']:.2f}) | {tool} | {spv:.2f} | {mb:.0f} | "
                         f"{agree:.3f} of {n} | {pts} | {kept} of {reg} |")
    if reals:
        lines += ["", f"## Projection for the paper's {PROJECTION_PHOTOS:,} photos", "",
                  "From the seconds a view above at 0.5 MP (the mean of the real scenes), one process "
                  "a machine, views spread evenly (densify's work units; OpenMVS has none of its own).", "",
                  "| tool | s / view | 1 machine | 64 machines |", "|---|---|---|---|"]
        for i, tool in enumerate(r[0] for r in reals[0]["rows"]):
            spv = np.mean([r["rows"][i][1] for r in reals])
            total = spv * PROJECTION_PHOTOS
            lines.append(f"| {tool} | {spv:.2f} | {total / 3600:.1f} h | {total / 64 / 60:.0f} min |")
    return "\n".join(lines) + "\n"


PRESETS = ("fast", "default", "thorough")
SIZES = (632, 816, 1155)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default=os.path.join(ROOT, "target/release/nrw-etl"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--size", type=int, default=360, help="longer side of the small synthetic views")
    ap.add_argument("--quick", action="store_true", help="synthetic scenes only, 4 photos")
    ap.add_argument("--parts", default="presets,sizes,real",
                    help="which sections to run: presets, sizes, real (comma-separated)")
    ap.add_argument("--pixel-samples", type=int, default=3,
                    help="rays a pixel per axis of the synthetic photos (1: the aliased centre ray)")
    ap.add_argument("--sized-photos", type=int, default=8, help="photos of the scene of each size")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs/bench/densify_openmvs.md"))
    args = ap.parse_args()
    args.quick_photos = 4
    parts = set(args.parts.split(","))
    args.openmvs = os.environ.get("NRW_OPENMVS_BIN")
    if not args.openmvs or not os.path.exists(os.path.join(args.openmvs, "DensifyPointCloud")):
        sys.exit("NRW_OPENMVS_BIN must name the folder of OpenMVS's InterfaceCOLMAP and "
                 "DensifyPointCloud (../shared/tools/build-openmvs.sh builds them)")
    args.openmvs_version = openmvs_version(args.openmvs)
    spec = lambda n: os.path.join(ROOT, "scenes", f"{n}.toml")
    synth, sized, reals = [], [], []
    with tempfile.TemporaryDirectory() as work:
        if "presets" in parts:
            for name, size in (("textured", args.size), ("wild", args.size), ("hard", 816)):
                made = make_scene(args, spec(name), name, work)
                synth.append(synthetic(args, made, name, size, PRESETS))
                print(f"{name}: done", file=sys.stderr)
        if "sizes" in parts:
            made = make_scene(args, spec("wild"), "wild_1mp", work, shorter=880,
                              count=args.sized_photos)
            for size in SIZES:
                sized.append(synthetic(args, made, f"wild, {args.sized_photos} photos", size,
                                       ("default",)))
                print(f"size {size}: done", file=sys.stderr)
        if "real" in parts and not args.quick:
            reals = [real(args, n, s, work) for n, s in (("sacre_coeur", 853), ("sceaux_castle", 816))]
    text = report(args, synth, sized, reals)
    with open(args.out, "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
