"""nerfstudio's own data parsers and datasets (nerfstudio 1.1.5 from PyPI, which needs torch) on
two exports of one dataset: `--layout nerfstudio` through `NerfstudioDataParser` and
`DepthDataset`, `--layout gsplat` through `ColmapDataParser` at downscale factors 1, 2 and 4.
Prints one JSON object. Runs only where torch is installed (never in CI: the Rust test that
calls it says when it skips).

What is measured, with nerfstudio's own objects only:
- `DepthDataset.get_data(k)`: the image, the mask (`get_image_mask_tensor_from_path`) and the
  depth (`get_depth_image_from_path`, × depth_unit_scale_factor × dataparser scale);
- the sparse points nerfstudio loads (`points3D_xyz`, in its oriented, scaled world) projected
  by its own cameras (camera_to_worlds, fx, fy, cx, cy; OpenGL axes) land on pixels whose
  depth it read is the point's camera z: the median relative difference over visible points;
- `ColmapDataParser` with `images_N/` and `masks_N/`: image and mask shapes equal the rescaled
  cameras' (floor rounding, its default), and fx equals the full-size fx / N.

usage: nerfstudio_torch.py NERFSTUDIO_EXPORT GSPLAT_EXPORT
"""

import importlib.metadata
import json
import sys
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from nerfstudio.data.dataparsers.colmap_dataparser import ColmapDataParserConfig
from nerfstudio.data.dataparsers.nerfstudio_dataparser import NerfstudioDataParserConfig
from nerfstudio.data.datasets.base_dataset import InputDataset
from nerfstudio.data.datasets.depth_dataset import DepthDataset

ns_dir, gs_dir = Path(sys.argv[1]), Path(sys.argv[2])
out = {"torch": torch.__version__, "nerfstudio_version": importlib.metadata.version("nerfstudio")}
# nerfstudio logs to standard output (rich's console): the JSON alone goes there.
result, sys.stdout = sys.stdout, sys.stderr

# --- transforms.json -------------------------------------------------------------------------
parser = NerfstudioDataParserConfig(data=ns_dir, load_3D_points=True).setup()
outputs = parser.get_dataparser_outputs("train")
dataset = DepthDataset(outputs)
cams = outputs.cameras
xyz = outputs.metadata["points3D_xyz"].double().numpy()
ns = {
    "train": len(outputs.image_filenames),
    "val": len(parser.get_dataparser_outputs("val").image_filenames),
    "masks": outputs.mask_filenames is not None,
    "depth_unit_scale_factor": outputs.metadata["depth_unit_scale_factor"],
    "points": len(xyz),
    "frames": [],
}
relative = []
for k in range(len(dataset)):
    data = dataset.get_data(k)
    h, w = int(cams.height[k]), int(cams.width[k])
    depth = data["depth_image"][..., 0].double().numpy()
    frame = {
        "image": list(data["image"].shape),
        "mask": list(data["mask"].shape) if "mask" in data else None,
        "masked": int((~data["mask"]).sum()) if "mask" in data else None,
        "masked_in_png": int((np.array(Image.open(outputs.mask_filenames[k])) == 0).sum()),
        "depth": list(depth.shape),
        "camera": [h, w],
    }
    c2w = cams.camera_to_worlds[k].double().numpy()
    cam = (xyz - c2w[:, 3]) @ c2w[:, :3]  # world -> camera, OpenGL axes
    x, y, z = cam[:, 0], -cam[:, 1], -cam[:, 2]
    fx, fy = float(cams.fx[k]), float(cams.fy[k])
    cx, cy = float(cams.cx[k]), float(cams.cy[k])
    front = z > 1e-9
    u = fx * x[front] / z[front] + cx
    v = fy * y[front] / z[front] + cy
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    zi = z[front][inside]
    d = depth[v[inside].astype(int), u[inside].astype(int)]
    seen = d > 0
    rel = np.abs(d[seen] - zi[seen]) / zi[seen]
    # Points hidden behind nearer ones are not what the pixel shows: keep the visible ones.
    visible = rel[rel < 0.05]
    frame["projected"] = int(inside.sum())
    frame["visible"] = int(len(visible))
    relative.extend(visible.tolist())
    ns["frames"].append(frame)
ns["median_relative_depth"] = float(np.median(relative)) if relative else None
ns["visible_points"] = len(relative)
out["nerfstudio"] = ns

# --- the COLMAP folder at downscale factors 1, 2, 4 -------------------------------------------
colmap = {}
full_fx = None
for factor in (1, 2, 4):
    cfg = ColmapDataParserConfig(
        data=gs_dir,
        colmap_path=Path("sparse/0"),
        images_path=Path("images"),
        masks_path=Path("masks"),
        downscale_factor=factor,
        load_3D_points=True,
    )
    o = cfg.setup().get_dataparser_outputs("train")
    ds = InputDataset(o)
    rows = []
    for k in range(len(ds)):
        data = ds.get_data(k)
        rows.append({
            "file": o.image_filenames[k].parent.name,
            "image": list(data["image"].shape[:2]),
            "mask": list(data["mask"].shape[:2]),
            "camera": [int(o.cameras.height[k]), int(o.cameras.width[k])],
            "fx": float(o.cameras.fx[k]),
        })
    if factor == 1:
        full_fx = [r["fx"] for r in rows]
    colmap[str(factor)] = {
        "views": len(rows),
        "folders": sorted({r["file"] for r in rows}),
        "shape_mismatches": sum(r["image"] != r["camera"] or r["mask"] != r["camera"] for r in rows),
        "fx_worst_relative": max(abs(r["fx"] * factor - f) / f for r, f in zip(rows, full_fx)),
        "first": rows[0],
    }
out["colmap"] = colmap
json.dump(out, result)
