"""nerfbaselines' own loaders (PyPI nerfbaselines 1.2.12, no torch) read an export of
`--layout gsplat` (its `colmap` loader, and at images_2 its own rescale of the intrinsics) or
`--layout nerfbaselines` (`load_dataset`, which follows nb-info.json): the split from
train_list.txt / test_list.txt, images, masks and points. Prints one JSON object of what it
read; tests/gsplat.rs compares it with the export and the dataset.

usage: gsplat_nerfbaselines.py EXPORT
"""

import json
import sys
from pathlib import Path

import numpy as np
from PIL import Image
from nerfbaselines.datasets import dataset_load_features, load_dataset
from nerfbaselines.datasets.colmap import load_colmap_dataset

root = Path(sys.argv[1])
features = frozenset({"color", "points3D_xyz", "points3D_rgb"})
described = (root / "nb-info.json").exists()
out = {"splits": {}}
for split in ("train", "test"):
    if described:
        ds = load_dataset(str(root), split=split, features=features)
        out["metadata"] = {k: ds["metadata"].get(k) for k in ("id", "scene", "evaluation_protocol")}
    else:
        ds = load_colmap_dataset(root, split=split, features=features)
        ds = dataset_load_features(ds, features=features, show_progress=False)
    names = [Path(p).name for p in ds["image_paths"]]
    views = []
    for i, p in enumerate(ds["image_paths"]):
        rel = Path(p).relative_to(root.resolve() / "images").as_posix()
        ours = np.array(Image.open(root / "images" / rel).convert("RGB"))
        mask_ours = np.array(Image.open(root / "masks" / rel)) > 0
        views.append(
            {
                "file": rel,
                "image_equal": bool(np.array_equal(ds["images"][i][..., :3], ours)),
                "mask_equal": bool(np.array_equal(ds["masks"][i], mask_ours)),
                "ignored": int((~ds["masks"][i]).sum()),
                "intrinsics": ds["cameras"].intrinsics[i].astype(float).tolist(),
                "size": ds["cameras"].image_sizes[i].tolist(),
                "pose": ds["cameras"].poses[i].astype(float).tolist(),
            }
        )
    out["splits"][split] = views
    out["points"] = len(ds["points3D_xyz"])

if described:
    print(json.dumps(out))
    sys.exit(0)

# images_2: nerfbaselines estimates the factor from the sizes and rescales K itself.
half = load_colmap_dataset(root, split="train", features=frozenset({"color"}), images_path="images_2")
half = dataset_load_features(half, features=frozenset({"color"}), show_progress=False)
out["images_2"] = [
    {
        "file": Path(p).relative_to(root.resolve() / "images_2").as_posix(),
        "intrinsics": half["cameras"].intrinsics[i].astype(float).tolist(),
        "size": half["cameras"].image_sizes[i].tolist(),
    }
    for i, p in enumerate(half["image_paths"])
]
print(json.dumps(out))
