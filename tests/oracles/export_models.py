"""The COLMAP models of an export, read by the consumers' own code: pycolmap 4.2.1 for every
layout's model, and nerfbaselines 1.2.12's `colmap` loader (no torch) where the layout is one
it reads (gsplat's `sparse/0`, nerfbaselines' `sparse`). For each image: how many keypoints
observe a 3D point, and how far each lies from where the image's own camera projects its
point (pycolmap's `img_from_cam`; for nerfbaselines, its intrinsics and camera-to-world poses).
Prints one JSON object; tests/export_models.rs compares it with the source model.

usage: export_models.py MODEL_DIR [nerfbaselines ROOT IMAGES_PATH COLMAP_PATH]
"""

import json
import sys
from pathlib import Path

import numpy as np
import pycolmap


def by_pycolmap(model_dir):
    rec = pycolmap.Reconstruction(model_dir)
    out = {}
    for image in rec.images.values():
        cam = rec.cameras[image.camera_id]
        pose = image.cam_from_world()
        dists = []
        for p in image.points2D:
            if not p.has_point3D():
                continue
            xyz = rec.points3D[p.point3D_id].xyz
            proj = cam.img_from_cam(pose * xyz)
            dists.append(float(np.linalg.norm(proj - p.xy)))
        out[image.name] = dists
    tracks = sum(len(p.track.elements) for p in rec.points3D.values())
    return {"images": out, "points": len(rec.points3D), "track_elements": tracks}


def by_nerfbaselines(root, images_path, colmap_path):
    from nerfbaselines.datasets.colmap import load_colmap_dataset

    features = frozenset({"points3D_xyz", "images_points3D_indices", "images_points2D_xy"})
    out = {}
    for split in ("train", "test"):
        ds = load_colmap_dataset(
            Path(root), split=split, features=features,
            images_path=images_path, colmap_path=colmap_path,
        )
        xyz = ds["points3D_xyz"].astype(np.float64)
        for i, path in enumerate(ds["image_paths"]):
            fx, fy, cx, cy = ds["cameras"].intrinsics[i].astype(np.float64)
            c2w = ds["cameras"].poses[i].astype(np.float64)
            r, t = c2w[:3, :3], c2w[:3, 3]
            idx = ds["images_points3D_indices"][i]
            xy = ds["images_points2D_xy"][i].astype(np.float64)
            cam = (xyz[idx] - t) @ r
            proj = np.stack([fx * cam[:, 0] / cam[:, 2] + cx, fy * cam[:, 1] / cam[:, 2] + cy], 1)
            name = Path(path).relative_to(Path(root).resolve() / images_path).as_posix()
            out[name] = np.linalg.norm(proj - xy, axis=1).tolist()
    return {"images": out}


result = {"pycolmap": by_pycolmap(sys.argv[1])}
if len(sys.argv) > 2 and sys.argv[2] == "nerfbaselines":
    result["nerfbaselines"] = by_nerfbaselines(sys.argv[3], sys.argv[4], sys.argv[5])
print(json.dumps(result))
