"""DUSt3R's MegaDepth loader (naver/dust3r dust3r/datasets/megadepth.py, `_load_data` and
`_get_views`, with dust3r/utils/image.py's `imread_cv2`), transcribed line by line since the
loader's base class needs torch, run on the `dust3r/` folder of a `--layout megadepth` export
with OpenCV's own JPEG and EXR readers. OpenCV 5's PyPI wheels carry no EXR codec (4.x's do,
behind OPENCV_IO_ENABLE_OPENEXR): there the EXR is read with the OpenEXR package, the one
departure from the transcription, and the JSON says which reader read it. Dumps each view's
depth as float64 .npy and prints one JSON object of what it read.

usage: megadepth_dust3r.py DUST3R_ROOT DUMP_DIR
"""

import json
import os
import os.path as osp
import sys

os.environ["OPENCV_IO_ENABLE_OPENEXR"] = "1"  # as dust3r/utils/image.py sets it
import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT, dump = sys.argv[1], sys.argv[2]
exr_reader = "cv2 " + cv2.__version__


def imread_cv2(path, options=cv2.IMREAD_COLOR):
    # dust3r/utils/image.py
    if path.endswith((".exr", "EXR")):
        options = cv2.IMREAD_ANYDEPTH
    img = cv2.imread(path, options)
    if img is None and path.endswith(".exr") and not cv2.haveImageReader(path):
        global exr_reader
        import OpenEXR

        exr_reader = "OpenEXR (this OpenCV has no EXR codec)"
        img = OpenEXR.File(path).channels()["Y"].pixels
    if img is None:
        raise IOError(f"Could not load image={path} with {options=}")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return img


# MegaDepth._load_data
with np.load(osp.join(ROOT, "all_metadata.npz")) as data:
    all_scenes = data["scenes"]
    all_images = data["images"]
    pairs = data["pairs"]

out = {"pairs": [], "views": {}}
for pair_idx in range(len(pairs)):
    # MegaDepth._get_views
    scene_id, im1_id, im2_id, score = pairs[pair_idx]
    scene, subscene = all_scenes[scene_id].split()
    seq_path = osp.join(ROOT, scene, subscene)
    out["pairs"].append([int(im1_id), int(im2_id), float(score)])
    for im_id in [im1_id, im2_id]:
        img = all_images[im_id]
        image = imread_cv2(osp.join(seq_path, img + ".jpg"))
        depthmap = imread_cv2(osp.join(seq_path, img + ".exr"))
        camera_params = np.load(osp.join(seq_path, img + ".npz"))
        intrinsics = np.float32(camera_params["intrinsics"])
        camera_pose = np.float32(camera_params["cam2world"])
        if str(img) in out["views"]:
            continue
        np.save(osp.join(dump, f"dust3r_{int(im_id)}.npy"), depthmap.astype(np.float64))
        out["views"][str(img)] = {
            "id": int(im_id),
            "image_shape": list(image.shape),
            "depth_shape": list(depthmap.shape),
            "depth_dtype": str(depthmap.dtype),
            "intrinsics": intrinsics.astype(float).tolist(),
            "cam2world": camera_pose.astype(float).tolist(),
            "rgb": image.astype(float).ravel().tolist(),
        }
out["fields"] = list(pairs.dtype.names)
out["exr_reader"] = exr_reader
print(json.dumps(out))
