"""graphdeco's own 3DGS loader (graphdeco-inria/gaussian-splatting at a checkout named by
GRAPHDECO_SRC; it needs torch, so never in CI) reads a `--layout gsplat` export with depth
regularisation on, as `train.py -s EXPORT -d depths` does: `scene.dataset_readers.
readColmapSceneInfo(path, "images", "depths", eval=False, train_test_exp=False)` (cameras,
depth_params.json with its med_scale, the points3D.ply it trains from) and
`utils.camera_utils.cameraList_from_camInfos` at resolution 1, whose `Camera` reads each depth
PNG, applies scale and offset and decides `depth_reliable`. Dumps each camera's inverse depth
as float64 .npy (DUMP/STEM.npy) and prints one JSON object of what it read.

Two shims, neither in the loader's path: `simple_knn._C` (a CUDA extension that
scene/gaussian_model.py imports for training) is an empty module, and `torch.Tensor.cuda` is
the identity (Camera moves its view matrices to the GPU; there is none here).

usage: gsplat_graphdeco_torch.py EXPORT GRAPHDECO_SRC DUMP
"""

import contextlib
import json
import os
import sys
import types

import numpy as np
import torch

root, src, dump = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, src)
knn = types.ModuleType("simple_knn")
knn._C = types.ModuleType("simple_knn._C")
knn._C.distCUDA2 = None
sys.modules["simple_knn"], sys.modules["simple_knn._C"] = knn, knn._C
torch.Tensor.cuda = lambda self, *a, **k: self

from scene.dataset_readers import readColmapSceneInfo  # noqa: E402
from utils.camera_utils import cameraList_from_camInfos  # noqa: E402

# The loader writes its progress to stdout: to stderr here, so stdout is the JSON alone.
with contextlib.redirect_stdout(sys.stderr):
    info = readColmapSceneInfo(root, "images", "depths", False, False)
    args = types.SimpleNamespace(resolution=1, data_device="cpu", train_test_exp=False)
    cameras = cameraList_from_camInfos(info.train_cameras, 1.0, args, False, False)
out = {"cameras": [], "points": int(info.point_cloud.points.shape[0]),
       "normals_nonzero": int((np.abs(info.point_cloud.normals).sum(axis=1) > 0).sum())}
for cam in cameras:
    stem = os.path.splitext(cam.image_name)[0]
    inv = cam.invdepthmap[0].numpy().astype(np.float64)
    np.save(os.path.join(dump, stem + ".npy"), inv)
    out["cameras"].append({
        "image_name": cam.image_name, "size": [cam.image_width, cam.image_height],
        "depth_shape": list(inv.shape), "reliable": bool(cam.depth_reliable),
        "depth_mask_zeros": int((cam.depth_mask == 0).sum()),
        "fovx": float(cam.FoVx), "fovy": float(cam.FoVy),
    })
json.dump(out, sys.stdout)
