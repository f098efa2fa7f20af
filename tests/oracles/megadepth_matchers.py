"""LoFTR's and RoMa's MegaDepth loaders, transcribed without torch, on a `--layout megadepth`
export; their pairs checked against the overlap matrix D2-Net's own preprocess_scene.py wrote
for the same export. Prints one JSON object.

LoFTR (zju3dv/LoFTR src/datasets/megadepth.py, MegaDepthDataset): `__init__`'s
`np.load(npz_path, allow_pickle=True)`, `['pair_infos'].copy()`, `del …['pair_infos']`, the
`pair_info[1] > min_overlap_score` filter; `__getitem__`'s unpacking
`(idx0, idx1), overlap_score, central_matches = self.pair_infos[idx]`, the image and depth
paths joined to the root, `read_megadepth_depth` (src/utils/dataset.py:
`np.array(h5py.File(path, 'r')['depth'])`), `intrinsics[idx].copy()` reshaped to 3 × 3 and
`np.matmul(T1, np.linalg.inv(T0))`. The list file is read as its data module reads it (one
name a line, `.npz` appended). torch's tensors are left out: they wrap these arrays.

RoMa (Parskatt/RoMa romatch/datasets/megadepth.py): `MegadepthBuilder.build_scenes`'s
`np.load(…, allow_pickle=True).item()`, `MegadepthScene.__init__`'s keys and its
`(overlaps > min_overlap) & (overlaps < max_overlap)` filter, `__getitem__`'s
`idx1, idx2 = self.pairs[pair_idx]`, intrinsics, `np.matmul(T2, np.linalg.inv(T1))`, the
image opened with PIL and `np.array(h5py.File(depth_ref, "r")["depth"])`.

usage: megadepth_matchers.py EXPORT D2NET_SCENE_INFO.npz SCENE
"""

import json
import os
import os.path as osp
import sys

import h5py
import numpy as np
from PIL import Image

root, theirs_path, scene = sys.argv[1], sys.argv[2], sys.argv[3]
theirs = np.load(theirs_path, allow_pickle=True)
overlap = theirs["overlap_matrix"]
n = overlap.shape[0]


def score(i, j):
    """The pair's score from D2-Net's matrix: the smaller of its two overlaps."""
    return min(overlap[i, j], overlap[j, i])


def central(i, j):
    """D2-Net's dicts' shared point nearest view i's principal point, as [y_i, x_i, y_j, x_j]."""
    a, b = theirs["points3D_id_to_2D"][i], theirs["points3D_id_to_2D"][j]
    k = theirs["intrinsics"][i]
    shared = [p for p in a if p in b]
    best = min(shared, key=lambda p: ((a[p][0] - k[0, 2]) ** 2 + (a[p][1] - k[1, 2]) ** 2, p))
    return [a[best][1], a[best][0], b[best][1], b[best][0]]


sharing = [(i, j) for i in range(n) for j in range(i + 1, n) if overlap[i, j] > 0]
out = {"views": n, "sharing_pairs": len(sharing)}


def views_read(info, i, j):
    """What both loaders do with a pair's views: images and depth open, K and the relative pose."""
    for idx in (i, j):
        img = osp.join(root, info["image_paths"][idx])
        depth = np.array(h5py.File(osp.join(root, info["depth_paths"][idx]), "r")["depth"])
        with Image.open(img) as im:
            if depth.shape != (im.height, im.width):
                return f"{img}: image {im.size}, depth {depth.shape}"
        if not np.array_equal(info["intrinsics"][idx].copy().reshape(3, 3), theirs["intrinsics"][idx]):
            return f"K of view {idx} differs from D2-Net's"
        if np.max(np.abs(info["poses"][idx] - theirs["poses"][idx])) > 1e-15:
            return f"pose of view {idx} differs from D2-Net's"
    t = np.matmul(info["poses"][j], np.linalg.inv(info["poses"][i]))
    if not np.allclose(t[3], [0, 0, 0, 1]):
        return "T_0to1 is not rigid"
    return None


# LoFTR: every band file of the list; min_overlap_score 0 (its training configs on these bands).
loftr = {"bands": {}, "problems": []}
listed = [line.split()[0] for line in open(osp.join(root, "index/trainvaltest_list/train_list.txt"))]
seen = []
for name in listed:
    lo, hi = (float(x) for x in name[len(scene) + 1:].split("_"))
    scene_info = np.load(osp.join(root, "index/scene_info_0.1_0.7", f"{name}.npz"), allow_pickle=True)
    pair_infos = scene_info["pair_infos"].copy()
    del scene_info["pair_infos"]
    pair_infos = [pair_info for pair_info in pair_infos if pair_info[1] > 0.0]
    want = sorted((i, j) for i, j in sharing if lo <= score(i, j) < hi)
    got = []
    for idx in range(len(pair_infos)):
        (idx0, idx1), overlap_score, central_matches = pair_infos[idx]
        got.append((int(idx0), int(idx1)))
        if overlap_score != score(idx0, idx1):
            loftr["problems"].append(f"{name} ({idx0}, {idx1}): score {overlap_score} != {score(idx0, idx1)}")
        if central_matches.shape != (1, 4) or list(central_matches[0]) != central(idx0, idx1):
            loftr["problems"].append(f"{name} ({idx0}, {idx1}): central match {central_matches.tolist()}")
        problem = views_read(scene_info, idx0, idx1)
        if problem:
            loftr["problems"].append(f"{name}: {problem}")
    if got != want:
        loftr["problems"].append(f"{name}: pairs {got} != {want}")
    loftr["bands"][name] = len(got)
    seen += got
loftr["keys"] = sorted(scene_info.keys())
out["loftr"] = loftr

# RoMa: the whole range (its builder's default min_overlap 0, max_overlap 1).
roma = {"problems": []}
scene_info = np.load(osp.join(root, "prep_scene_info", f"{scene}.npy"), allow_pickle=True).item()
roma["keys"] = sorted(scene_info.keys())
pairs, overlaps = scene_info["pairs"], scene_info["overlaps"]
threshold = (overlaps > 0.0) & (overlaps < 1.0)
pairs, overlaps = pairs[threshold], overlaps[threshold]
roma["dtypes"] = [str(scene_info["pairs"].dtype), str(scene_info["overlaps"].dtype)]
got = [(int(a), int(b)) for a, b in scene_info["pairs"]]
if got != sharing:
    roma["problems"].append(f"pairs {got} != {sharing}")
for pair_idx in range(len(pairs)):
    idx1, idx2 = pairs[pair_idx]
    if overlaps[pair_idx] != score(idx1, idx2):
        roma["problems"].append(f"({idx1}, {idx2}): overlap {overlaps[pair_idx]} != {score(idx1, idx2)}")
    problem = views_read(scene_info, idx1, idx2)
    if problem:
        roma["problems"].append(problem)
roma["pairs"] = len(pairs)
out["roma"] = roma
json.dump(out, sys.stdout)
