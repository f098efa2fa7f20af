#!/usr/bin/env python3
"""What the trainer-signal exports' accuracy costs in time: regenerates docs/bench/exports.md.

    python3 docs/bench/exports.py [--bin target/release/nrw-etl] [--repeat 3]

On the real scenes of ../shared/data (ingested with --undistort at the paper's 600 px, split
with 2 held out), each row times one way of making a trainer's files under GNU time (wall
clock, peak memory) and states its accuracy:

- Image pyramid. Ours: `export --layout gsplat` (images_2/4/8 of whole blocks, plus masks,
  depth priors and the model, i.e. the whole export). Peer, in the same run: the pyramid as
  gsplat's parser makes it when a folder is missing (examples/datasets/colmap.py's
  `_resize_image_folder`: PIL BICUBIC to round(size / N), re-implemented here in its few lines
  of PIL so the peer needs no torch). Accuracy: the worst distance, over every image and level,
  between where gsplat's parser puts the principal point (K / N, rescaled by the first image's
  actual / expected size) and where it is in that level's pixels (COLMAP's convention: K times
  the level's size / the image's size, per axis).
- scene_info. Ours: `export --layout megadepth` (scene_info with the HDF5 depth, text model,
  DUSt3R folder, pair indices, IMC 2022: the whole export). Peer, in the same run: D2-Net's
  own preprocess_scene.py on that export (scene_info alone). Accuracy: the largest difference between the two
  scene_info files' overlap, scale-ratio and angle matrices.

Needs numpy, Pillow, h5py and imagesize; ../shared/data and ../shared/consumers/d2-net.
Not a timed test: a report, with the machine's CPU flags.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared"


def timed(cmd):
    """(seconds, peak MB, stdout+stderr) of one command under GNU time."""
    r = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed:\n{r.stderr[-3000:]}")
    clock = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)", r.stderr).group(1)
    secs = 0.0
    for part in clock.split(":"):
        secs = secs * 60 + float(part)
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr).group(1))
    return secs, rss / 1024, r.stdout + r.stderr


def best(runs):
    """The fastest of repeated runs (seconds, its peak MB)."""
    return min(runs, key=lambda r: r[0])[:2]


def cpu_flags():
    flags = Path("/proc/cpuinfo").read_text().split("flags\t\t: ", 1)[1].split("\n", 1)[0].split()
    wanted = [f for f in flags if f in ("avx2", "avx512f", "fma", "sse4_2")]
    model = re.search(r"model name\t: (.*)", Path("/proc/cpuinfo").read_text()).group(1)
    return f"{model}; {os.cpu_count()} cores; {' '.join(wanted)}"


PEER_PYRAMID = r'''
import sys, os, numpy as np
from PIL import Image
src, dst = sys.argv[1], sys.argv[2]
for factor in (2, 4, 8):
    out = os.path.join(dst, f"images_{factor}_png")
    for dp, dn, fn in os.walk(src):
        for f in fn:
            rel = os.path.relpath(os.path.join(dp, f), src)
            image = np.array(Image.open(os.path.join(src, rel)).convert("RGB"))
            size = (int(round(image.shape[1] / factor)), int(round(image.shape[0] / factor)))
            resized = np.array(Image.fromarray(image).resize(size, Image.BICUBIC))
            path = os.path.join(out, os.path.splitext(rel)[0] + ".png")
            os.makedirs(os.path.dirname(path), exist_ok=True)
            Image.fromarray(resized).save(path)
'''


def read_cameras(model):
    """{image name: (w, h, fx, fy, cx, cy)} of a PINHOLE binary model (one camera per image)."""
    import pycolmap

    rec = pycolmap.Reconstruction(str(model))
    out = {}
    for im in rec.images.values():
        c = rec.cameras[im.camera_id]
        out[im.name] = (c.width, c.height, *c.params[:4])
    return out


def gsplat_pp_error(cams, level_sizes, factor, whole_blocks):
    """Worst principal-point error (level pixels) of gsplat's parser on levels of these sizes:
    K / factor, rescaled by the first image's actual / (width // factor), against where the
    principal point is in the level: K / factor for whole blocks (each level pixel is an exact
    factor × factor block), K times the level's size / the image's size for a resize that maps
    the image's edges to the level's (PIL's)."""
    names = sorted(cams)
    w0, h0 = cams[names[0]][:2]
    aw, ah = level_sizes[names[0]]
    sx, sy = aw / (w0 // factor), ah / (h0 // factor)
    worst = 0.0
    for n in names:
        w, h, fx, fy, cx, cy = cams[n]
        lw, lh = level_sizes[n]
        gx, gy = cx / factor * sx, cy / factor * sy
        tx, ty = (cx / factor, cy / factor) if whole_blocks else (cx * lw / w, cy * lh / h)
        worst = max(worst, abs(gx - tx), abs(gy - ty))
    return worst


def sizes_of(folder, names, ext_png=True):
    out = {}
    for n in names:
        p = folder / (os.path.splitext(n)[0] + ".png" if ext_png else n)
        out[n] = Image.open(p).size
    return out


def scene_rows(binary, scene, tmp, repeat):
    ds = tmp / f"{scene}_ds"
    subprocess.run([binary, "ingest", str(SHARED / "data" / scene), "--out", str(ds), "--undistort",
                    "--max-empty", "1", "--quiet"], check=True)
    subprocess.run([binary, "split", str(ds), "--val", "2"], check=True, capture_output=True)
    gs = tmp / f"{scene}_gs"
    ours = best([timed([binary, "export", str(ds), "--layout", "gsplat", "--out", str(gs), "--quiet"])
                 for _ in range(repeat)])
    cams = read_cameras(gs / "sparse/0")
    names = sorted(cams)
    ours_err = max(gsplat_pp_error(cams, sizes_of(gs / f"images_{f}", names, False), f, True)
                   for f in (2, 4, 8))
    peer_out = tmp / f"{scene}_peer"
    peer = best([timed([sys.executable, "-c", PEER_PYRAMID, str(gs / "images"), str(peer_out)])
                 for _ in range(repeat)])
    peer_err = max(gsplat_pp_error(cams, sizes_of(peer_out / f"images_{f}_png", names), f, False)
                   for f in (2, 4, 8))
    views = len(names)
    pyramid = (scene, views, ours, ours_err, peer, peer_err)

    md = tmp / f"{scene}_md"
    ours_md = best([timed([binary, "export", str(ds), "--layout", "megadepth", "--name", scene,
                           "--out", str(md), "--quiet"]) for _ in range(repeat)])
    d2 = tmp / f"{scene}_d2"
    d2.mkdir(exist_ok=True)
    peer_md = best([timed([sys.executable, str(SHARED / "consumers/d2-net/preprocess_scene.py"),
                           "--base_path", str(md), "--scene_id", scene, "--output_path", str(d2)])
                    for _ in range(repeat)])
    a = np.load(md / f"scene_info/{scene}.npz", allow_pickle=True)
    b = np.load(d2 / f"{scene}.npz", allow_pickle=True)
    diff = max(float(np.abs(a[k] - b[k]).max()) for k in ("overlap_matrix", "scale_ratio_matrix", "angles"))
    info = (scene, views, ours_md, peer_md, diff)
    return pyramid, info


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", default=str(ROOT / "target/release/nrw-etl"))
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    pyramids, infos = [], []
    with tempfile.TemporaryDirectory() as t:
        for scene in ("sacre_coeur", "sceaux_castle"):
            p, i = scene_rows(args.bin, scene, Path(t), args.repeat)
            pyramids.append(p)
            infos.append(i)
    out = ROOT / "docs/bench/exports.md"
    with open(out, "w") as f:
        f.write("# Trainer-signal exports: accuracy against time\n\n")
        f.write(f"Made by `python3 docs/bench/exports.py` on {time.strftime('%Y-%m-%d')}; {cpu_flags()}. "
                "Each figure is the fastest of the repeats; peak memory is that run's.\n\n")
        f.write("## Image pyramid (images_2, images_4, images_8)\n\n")
        f.write("| scene | views | ours: `export --layout gsplat` s | peak MB | principal point error px | "
                "peer: gsplat's PIL bicubic to round(size / N) s | peak MB | principal point error px | ratio |\n")
        f.write("|---|---|---|---|---|---|---|---|---|\n")
        for scene, n, (s, m), e, (ps, pm), pe in pyramids:
            f.write(f"| {scene} | {n} | {s:.2f} | {m:.0f} | {e:.1e} | {ps:.2f} | {pm:.0f} | {pe:.3f} | "
                    f"{ps / s:.2f}× |\n")
        f.write("\nOurs is the whole export (levels, masks, depth priors at every level, model); the peer makes "
                "only the three image levels. The error is where gsplat's parser puts the principal point "
                "against where it is in the level's pixels: whole blocks make gsplat's K / N exact; "
                "round(size / N) with bicubic resizing scales each image by round(size / N) / size, which "
                "gsplat's parser assumes is 1 / N (rescaling by the first image's ratio only).\n\n")
        f.write("## MegaDepth scene_info\n\n")
        f.write("| scene | views | ours: `export --layout megadepth` s | peak MB | peer: D2-Net's preprocess_scene.py s "
                "| peak MB | ratio | largest difference (overlap, scale ratio, angle) |\n")
        f.write("|---|---|---|---|---|---|---|---|\n")
        for scene, n, (s, m), (ps, pm), d in infos:
            f.write(f"| {scene} | {n} | {s:.2f} | {m:.0f} | {ps:.2f} | {pm:.0f} | {ps / s:.2f}× | {d:.1e} |\n")
        f.write("\nOurs writes the whole layout (photos, HDF5 depth, the text model, scene_info, DUSt3R's "
                "folder, LoFTR's and RoMa's pair indices, IMC 2022's csvs and JPEGs); the peer reads that layout and writes scene_info alone.\n")
    print(out.read_text())


if __name__ == "__main__":
    main()
