"""Compares the scene_info D2-Net's preprocess_scene.py wrote from a `--layout megadepth` export
with the export's own scene_info/NAME.npz, and dumps each depth .h5 (read with h5py) as a
float64 .npy for tests/megadepth.rs to compare with the dataset. Prints one JSON object.

usage: megadepth_d2net.py THEIRS.npz OURS.npz EXPORT DUMP_DIR
"""

import json
import sys
from pathlib import Path

import h5py
import numpy as np

theirs = np.load(sys.argv[1], allow_pickle=True)
ours = np.load(sys.argv[2], allow_pickle=True)
export, dump = Path(sys.argv[3]), Path(sys.argv[4])
out = {"keys_ours": sorted(ours.files), "keys_theirs": sorted(theirs.files)}
for key in ("image_paths", "depth_paths"):
    out[key] = [list(map(str, theirs[key])), list(map(str, ours[key]))]
for key in ("intrinsics", "poses", "overlap_matrix", "scale_ratio_matrix", "angles", "n_points3D"):
    a, b = np.asarray(theirs[key]), ours[key]
    out[key] = {
        "shape": [list(a.shape), list(b.shape)],
        "dtype": [str(a.dtype), str(b.dtype)],
        "max_abs": float(np.max(np.abs(a.astype(np.float64) - b.astype(np.float64)))) if a.shape == b.shape and a.size else None,
        "valid_pairs": int(np.sum(b > 0)) if key in ("overlap_matrix", "scale_ratio_matrix") else None,
    }
# The per-view dicts: same keys in the same (insertion) order, [x, y] lists equal, normalised
# depths numpy float64 scalars within float tolerance.
same_2d, nd_max, nd_types = True, 0.0, set()
for a, b in zip(theirs["points3D_id_to_2D"], ours["points3D_id_to_2D"]):
    same_2d &= list(a.items()) == list(b.items())
for a, b in zip(theirs["points3D_id_to_ndepth"], ours["points3D_id_to_ndepth"]):
    same_2d &= list(a.keys()) == list(b.keys())
    nd_max = max([nd_max] + [abs(float(a[k]) - float(b[k])) for k in a])
    nd_types |= {type(v).__name__ for v in b.values()}
out["dicts"] = {
    "same_2d_and_keys": bool(same_2d),
    "ndepth_max_abs": nd_max,
    "ndepth_types": sorted(nd_types),
    "lengths": [len(theirs["points3D_id_to_2D"]), len(ours["points3D_id_to_2D"])],
}
depths = []
for i, rel in enumerate(theirs["depth_paths"]):
    with h5py.File(export / str(rel), "r") as f:
        d = f["depth"][()]
    np.save(dump / f"{i}.npy", d.astype(np.float64))
    depths.append({"path": str(rel), "shape": list(d.shape), "dtype": str(d.dtype)})
out["depths"] = depths
print(json.dumps(out))
