"""RoMa itself (romatch 0.1.2 from PyPI, which needs torch: never in CI) reads a
`--layout megadepth` export, and its own ground-truth warp carries each view's SfM observations
onto the other view's. Prints one JSON object.

RoMa's code, not a transcription: `MegadepthBuilder(data_root=EXPORT)` lists
`prep_scene_info/`, `build_scenes(split="custom", …)` loads SCENE.npy into a `MegadepthScene`,
whose `__getitem__` opens both images and depth `.h5` files and returns the resized images and
depths, K1, K2 (scaled by `scale_intrinsic` to its 512 x 384 grid) and T_1to2. Then
`romatch.utils.utils.warp_kpts` — what `get_gt_warp`, the warp its training loss is computed
against, runs on every grid point — warps view A's observations (D2-Net's
`points3D_id_to_2D` in the export's scene_info, put on RoMa's grid) with RoMa's depth, K and
pose; where RoMa calls the warp valid (depth there, inside B, depths agreeing within 5%), the
distance to view B's own observation of the same point is the error, in RoMa's pixels.

Only observations whose pixel in A's depth file holds the point's own depth (within 1%, the
point from the export's Undistorted_SfM model) are warped: elsewhere the file holds another
surface or a hole, and no warp, RoMa's or ours, could land on B's observation. The same
observations warped independently (numpy, the export's scene_info.npz: nearest depth, K and
poses at the stored size, scaled to RoMa's grid after) give the error the data itself allows.

usage: megadepth_roma_torch.py EXPORT SCENE
"""

import json
import os
import sys

import h5py
import numpy as np
import torch
from PIL import Image
from romatch.datasets.megadepth import MegadepthBuilder
from romatch.utils.utils import warp_kpts

root, scene = sys.argv[1], sys.argv[2]
ours = np.load(os.path.join(root, "scene_info", f"{scene}.npz"), allow_pickle=True)
tracks = ours["points3D_id_to_2D"]
points = {}
for line in open(os.path.join(root, "Undistorted_SfM", scene, "sparse-txt", "points3D.txt")):
    if line.strip() and not line.startswith("#"):
        f = line.split()
        points[int(f[0])] = np.array([float(v) for v in f[1:4]])


def holds_the_point(idx, p):
    """Whether view idx's depth file, at its observation of point p, holds p's depth (1%)."""
    x, y = tracks[idx][p]
    depth = depths[idx]
    if not (0 <= x < depth.shape[1] and 0 <= y < depth.shape[0]):
        return False
    pose = ours["poses"][idx]
    z = (pose[:3, :3] @ points[p] + pose[:3, 3])[2]
    return abs(depth[int(y), int(x)] - z) <= 0.01 * z


depths = {}
sizes = {}  # view index -> (width, height) of its stored image, as PIL opens it

builder = MegadepthBuilder(data_root=root)
scenes = builder.build_scenes(split="custom", scene_names=[f"{scene}.npy"])
out = {"scenes": len(scenes), "problems": []}
s = scenes[0]
out["pairs"] = len(s)
stored = np.load(os.path.join(root, "prep_scene_info", f"{scene}.npy"), allow_pickle=True).item()
out["stored_pairs"] = len(stored["pairs"])
errors, independent, observations, valid = [], [], 0, 0


def warp_independently(i, j, shared):
    """B's pixels of A's observations by the export's scene_info.npz alone (stored size)."""
    ki, kj = ours["intrinsics"][i], ours["intrinsics"][j]
    t = ours["poses"][j] @ np.linalg.inv(ours["poses"][i])
    out = []
    for p in shared:
        x, y = tracks[i][p]
        cam = np.linalg.inv(ki) @ np.array([x, y, 1.0]) * depths[i][int(y), int(x)]
        u = kj @ (t[:3, :3] @ cam + t[:3, 3])
        out.append(u[:2] / u[2])
    return np.array(out)


for k in range(len(s)):
    d = s[k]
    idx1, idx2 = (int(i) for i in s.pairs[k])
    ht, wt = s.ht, s.wt
    for key, shape in (("im_A", (3, ht, wt)), ("im_B", (3, ht, wt)),
                       ("im_A_depth", (ht, wt)), ("im_B_depth", (ht, wt))):
        if tuple(d[key].shape) != shape:
            out["problems"].append(f"pair {k}: {key} {tuple(d[key].shape)} != {shape}")
    for idx, path in ((idx1, d["im_A_path"]), (idx2, d["im_B_path"])):
        sizes[idx] = Image.open(path).size
        depths[idx] = np.array(h5py.File(os.path.join(root, ours["depth_paths"][idx]), "r")["depth"])
    a, b = tracks[idx1], tracks[idx2]
    shared = sorted(p for p in a if p in b and holds_the_point(idx1, p))
    if not shared:
        continue
    (wa, ha), (wb, hb) = sizes[idx1], sizes[idx2]
    # A's observations on RoMa's grid, normalised as warp_kpts takes them ([0, w] -> [-1, 1]).
    xa = np.array([[a[p][0] * wt / wa, a[p][1] * ht / ha] for p in shared])
    xb = np.array([[b[p][0] * wt / wb, b[p][1] * ht / hb] for p in shared])
    kpts = torch.from_numpy(np.stack([2 * xa[:, 0] / wt - 1, 2 * xa[:, 1] / ht - 1], -1))[None]
    mask, warped = warp_kpts(kpts.double(), d["im_A_depth"][None].double(),
                             d["im_B_depth"][None].double(), d["T_1to2"][None].double(),
                             d["K1"][None].double(), d["K2"][None].double())
    w = warped[0].numpy()
    px = np.stack([(w[:, 0] + 1) / 2 * wt, (w[:, 1] + 1) / 2 * ht], -1)
    m = mask[0].numpy().astype(bool)
    observations += len(shared)
    valid += int(m.sum())
    errors += list(np.linalg.norm(px[m] - xb[m], axis=1))
    mine = warp_independently(idx1, idx2, shared) * np.array([wt / wb, ht / hb])
    independent += list(np.linalg.norm(mine - xb, axis=1))
out["observations"] = observations
out["valid"] = valid
out["median_px"] = float(np.median(errors)) if errors else None
out["p90_px"] = float(np.percentile(errors, 90)) if errors else None
out["independent_median_px"] = float(np.median(independent)) if independent else None
out["grid"] = [s.wt, s.ht]
json.dump(out, sys.stdout)
