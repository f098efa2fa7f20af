"""RoMa, LoFTR and DUSt3R themselves (they need torch: never in CI) read a `--layout megadepth`
export: RoMa's and LoFTR's own ground-truth warps carry view A's SfM observations onto view B's,
and DUSt3R's own point maps hold the SfM points. Prints one JSON object:
{"roma": …, "loftr": … or null, "dust3r": … or null}.

Their code, not a transcription:
- RoMa (romatch 0.1.2 from PyPI): `MegadepthBuilder(data_root=EXPORT)` lists
  `prep_scene_info/`, `build_scenes(split="custom", …)` loads SCENE.npy into a
  `MegadepthScene`, whose `__getitem__` opens both images and depth `.h5` files and returns them
  resized to its 512 x 384 grid, K1, K2 (scaled by `scale_intrinsic`) and T_1to2; then
  `romatch.utils.utils.warp_kpts` (what `get_gt_warp`, the target of its training loss, runs on
  every grid point; bilinear depth, depths agreeing within 5%).
- LoFTR (zju3dv/LoFTR's `src/`, a checkout named by LOFTR_SRC; not packaged): every band file
  of `index/trainvaltest_list/train_list.txt` through `MegaDepthDataset` with its outdoor
  training settings (mode "train", min_overlap_score 0, img_resize 640, df 8, image and depth
  padding), then `src.loftr.utils.geometry.warp_kpts` (what its coarse supervision runs;
  nearest depth, depths agreeing within 20%) at the original resolution, as LoFTR warps.
- DUSt3R (naver/dust3r's `dust3r/`, a checkout named by DUST3R_SRC; not packaged): its
  `MegaDepth` dataset over `dust3r/` (split None, resolution 512 x 384, seed 777), whose
  `__getitem__` crops and resizes each view around its principal point and computes `pts3d`
  (world points a pixel) and `valid_mask` with its own geometry; each SfM point whose depth the
  view's file holds is projected with DUSt3R's final K and cam2world, and the point map there
  is compared with the point. And its `opencv_to_colmap_intrinsics` turns each view's K back
  into the view's COLMAP K.

Only observations whose pixel in A's depth file holds the point's own depth (within 1%, the
point from the export's Undistorted_SfM model) are warped: elsewhere the file holds another
surface or a hole, and no warp could land on B's observation. The same observations warped
independently (numpy, the export's scene_info.npz: nearest depth, K and poses at the stored
size) give the error the data itself allows.

usage: megadepth_torch.py EXPORT SCENE [LOFTR_SRC|- [DUST3R_SRC]]
"""

import json
import os
import sys

import h5py
import numpy as np
import torch
from PIL import Image

root, scene = sys.argv[1], sys.argv[2]
loftr_src = sys.argv[3] if len(sys.argv) > 3 and sys.argv[3] != "-" else None
dust3r_src = sys.argv[4] if len(sys.argv) > 4 else None
ours = np.load(os.path.join(root, "scene_info", f"{scene}.npz"), allow_pickle=True)
tracks = ours["points3D_id_to_2D"]
depths = [np.array(h5py.File(os.path.join(root, p), "r")["depth"]) for p in ours["depth_paths"]]
sizes = [Image.open(os.path.join(root, p)).size for p in ours["image_paths"]]
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


def observations(i, j):
    """The points i and j share whose depth i's file holds: (ids, i's pixels, j's pixels)."""
    shared = sorted(p for p in tracks[i] if p in tracks[j] and holds_the_point(i, p))
    return (shared, np.array([tracks[i][p] for p in shared]).reshape(-1, 2),
            np.array([tracks[j][p] for p in shared]).reshape(-1, 2))


def warp_independently(i, j, xa):
    """B's pixels of A's pixels `xa` by the export's scene_info.npz alone (stored size)."""
    ki, kj = ours["intrinsics"][i], ours["intrinsics"][j]
    t = ours["poses"][j] @ np.linalg.inv(ours["poses"][i])
    out = []
    for x, y in xa:
        cam = np.linalg.inv(ki) @ np.array([x, y, 1.0]) * depths[i][int(y), int(x)]
        u = kj @ (t[:3, :3] @ cam + t[:3, 3])
        out.append(u[:2] / u[2])
    return np.array(out).reshape(-1, 2)


class Tally:
    """Errors of a consumer's warp against B's observations, beside the independent warp's."""

    def __init__(self):
        self.errors, self.independent, self.observations, self.valid = [], [], 0, 0

    def add(self, mask, warped, xb, mine):
        self.observations += len(xb)
        self.valid += int(mask.sum())
        self.errors += list(np.linalg.norm(warped[mask] - xb[mask], axis=1))
        self.independent += list(np.linalg.norm(mine - xb, axis=1))

    def into(self, out):
        med = lambda e: float(np.median(e)) if e else None
        # Medians in pixels (RoMa's grid, LoFTR's stored size).
        out.update(observations=self.observations, valid=self.valid, median=med(self.errors),
                   p90_px=float(np.percentile(self.errors, 90)) if self.errors else None,
                   independent_median=med(self.independent))
        return out


def roma():
    from romatch.datasets.megadepth import MegadepthBuilder
    from romatch.utils.utils import warp_kpts

    scenes = MegadepthBuilder(data_root=root).build_scenes(split="custom", scene_names=[f"{scene}.npy"])
    s = scenes[0]
    stored = np.load(os.path.join(root, "prep_scene_info", f"{scene}.npy"), allow_pickle=True).item()
    out = {"scenes": len(scenes), "pairs": len(s), "stored_pairs": len(stored["pairs"]),
           "grid": [s.wt, s.ht], "problems": []}
    tally = Tally()
    for k in range(len(s)):
        d = s[k]
        i, j = (int(v) for v in s.pairs[k])
        ht, wt = s.ht, s.wt
        for key, shape in (("im_A", (3, ht, wt)), ("im_B", (3, ht, wt)),
                           ("im_A_depth", (ht, wt)), ("im_B_depth", (ht, wt))):
            if tuple(d[key].shape) != shape:
                out["problems"].append(f"pair {k}: {key} {tuple(d[key].shape)} != {shape}")
        _, xa, xb = observations(i, j)
        if not len(xa):
            continue
        (wa, ha), (wb, hb) = sizes[i], sizes[j]
        # A's observations on RoMa's grid, normalised as its warp takes them ([0, w] -> [-1, 1]).
        ga, gb = xa * [wt / wa, ht / ha], xb * [wt / wb, ht / hb]
        kpts = torch.from_numpy(np.stack([2 * ga[:, 0] / wt - 1, 2 * ga[:, 1] / ht - 1], -1))[None]
        mask, warped = warp_kpts(kpts.double(), d["im_A_depth"][None].double(),
                                 d["im_B_depth"][None].double(), d["T_1to2"][None].double(),
                                 d["K1"][None].double(), d["K2"][None].double())
        w = warped[0].numpy()
        px = np.stack([(w[:, 0] + 1) / 2 * wt, (w[:, 1] + 1) / 2 * ht], -1)
        tally.add(mask[0].numpy().astype(bool), px, gb, warp_independently(i, j, xa) * [wt / wb, ht / hb])
    return tally.into(out)


def loftr():
    sys.path.insert(0, loftr_src)
    from src.datasets.megadepth import MegaDepthDataset
    import importlib.util

    # geometry.py by its file: the package's __init__ imports the whole model, whose kornia
    # import (kornia.utils.grid) today's kornia no longer has.
    spec = importlib.util.spec_from_file_location(
        "loftr_geometry", os.path.join(loftr_src, "src/loftr/utils/geometry.py"))
    geometry = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(geometry)
    warp_kpts = geometry.warp_kpts

    listed = [line.split()[0] for line in open(os.path.join(root, "index/trainvaltest_list/train_list.txt"))]
    out = {"bands": len(listed), "pairs": 0, "problems": []}
    tally = Tally()
    for name in listed:
        npz = os.path.join(root, "index/scene_info_0.1_0.7", f"{name}.npz")
        ds = MegaDepthDataset(root, npz, mode="train", min_overlap_score=0.0, img_resize=640,
                              df=8, img_padding=True, depth_padding=True)
        out["pairs"] += len(ds)
        for k in range(len(ds)):
            d = ds[k]
            (i, j), _, _ = ds.pair_infos[k]
            for side, idx in (("0", i), ("1", j)):
                # The resized image LoFTR reports through scale (stored size / resized size):
                # the longer side 640, both sides whole multiples of df, inside the padding.
                w, h = sizes[idx]
                scale = d[f"scale{side}"].numpy().astype(np.float64)
                resized = (round(w / scale[0]), round(h / scale[1]))
                if d[f"image{side}"].shape != (1, 640, 640) or d[f"depth{side}"].shape != (2000, 2000):
                    out["problems"].append(f"{name} pair {k}: padded shapes {d['image' + side].shape}")
                if any(r % 8 for r in resized) or not 632 < max(resized) <= 640:
                    out["problems"].append(f"{name} pair {k}: view {idx} ({w}x{h}) resized to {resized}")
            _, xa, xb = observations(i, j)
            if not len(xa):
                continue
            mask, warped = warp_kpts(torch.from_numpy(xa).float()[None], d["depth0"][None],
                                     d["depth1"][None], d["T_0to1"][None], d["K0"][None], d["K1"][None])
            tally.add(mask[0].numpy().astype(bool), warped[0].numpy(), xb, warp_independently(i, j, xa))
    return tally.into(out)


def dust3r():
    sys.path.insert(0, dust3r_src)
    from dust3r.datasets.megadepth import MegaDepth
    from dust3r.utils.geometry import opencv_to_colmap_intrinsics

    ds = MegaDepth(split=None, ROOT=os.path.join(root, "dust3r"), resolution=(512, 384), seed=777)
    stems = {os.path.splitext(os.path.basename(p))[0]: i for i, p in enumerate(ours["image_paths"])}
    colmap_k = {}
    for line in open(os.path.join(root, "Undistorted_SfM", scene, "sparse-txt", "cameras.txt")):
        if line.strip() and not line.startswith("#"):
            f = line.split()
            fx, fy, cx, cy = (float(v) for v in f[4:8])
            colmap_k[int(f[0])] = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    camera_of = {}
    for line in open(os.path.join(root, "Undistorted_SfM", scene, "sparse-txt", "images.txt")):
        f = line.split()
        if len(f) == 10 and not line.startswith("#"):
            camera_of[os.path.splitext(f[9])[0]] = int(f[8])
    out = {"pairs": len(ds), "problems": [], "k_max_abs": 0.0}
    rel, independent, observations, valid = [], [], 0, 0
    for k in range(len(ds)):
        for v in ds[k]:
            idx = stems[v["instance"]]
            # The npz's K (OpenCV's) back in COLMAP's, by DUSt3R's own conversion.
            npz = np.load(os.path.join(root, "dust3r", scene, "0", v["instance"] + ".npz"))
            back = opencv_to_colmap_intrinsics(npz["intrinsics"])
            diff = float(np.abs(back - colmap_k[camera_of[v["instance"]]]).max())
            out["k_max_abs"] = max(out["k_max_abs"], diff)
            kk, c2w, pts, mask = v["camera_intrinsics"], v["camera_pose"], v["pts3d"], v["valid_mask"]
            h, w = mask.shape
            if v["img"].shape[1:] != (h, w) or pts.shape != (h, w, 3):
                out["problems"].append(f"{v['instance']}: shapes {v['img'].shape} {pts.shape}")
            r, t = c2w[:3, :3].astype(np.float64), c2w[:3, 3].astype(np.float64)
            pose = ours["poses"][idx]
            for p in tracks[idx]:
                if not holds_the_point(idx, p):
                    continue
                cam = r.T @ (points[p] - t)
                u = kk.astype(np.float64) @ cam
                col, row = int(round(u[0] / u[2])), int(round(u[1] / u[2]))
                if not (0 <= col < w and 0 <= row < h):
                    continue
                observations += 1
                z = cam[2]
                if mask[row, col]:
                    valid += 1
                    rel.append(np.linalg.norm(pts[row, col] - points[p]) / z)
                # The same point from the export's scene_info.npz and depth at the stored size.
                x, y = tracks[idx][p]
                ray = np.linalg.inv(ours["intrinsics"][idx]) @ np.array([x, y, 1.0]) * depths[idx][int(y), int(x)]
                world = pose[:3, :3].T @ (ray - pose[:3, 3])
                independent.append(np.linalg.norm(world - points[p]) / z)
    out.update(observations=observations, valid=valid,
               # Medians relative to the point's depth.
               median=float(np.median(rel)) if rel else None,
               independent_median=float(np.median(independent)) if independent else None)
    return out


json.dump({"roma": roma(), "loftr": loftr() if loftr_src else None,
           "dust3r": dust3r() if dust3r_src else None}, sys.stdout)
