#!/usr/bin/env python3
"""Reads an `export --layout nerfw` folder the way NeRF-W loaders do (dev-time oracle only).

usage: nerfw_reader.py EXPORT_DIR
Transcribes the lines of kwea123/nerf_pl's datasets/phototourism.py
(PhototourismDataset.read_meta, which Ha-NeRF copies) that define the format: the first *.tsv
of the folder, read tab-separated with a header; image ids by name from
dense/sparse/images.bin; K from camdata[image_id].params[0:4]; c2w poses with the
"down right back" -> "right up back" column swap; per-image near/far as the 0.1 and 99.9
percentiles of the depths of the points3D in front of the camera; the train/test lists; each
image opened from dense/images/filename. The model is read with pycolmap instead of nerf_pl's
copy of COLMAP's read_write_model.py (the same binary format). pandas is replaced by csv with
the same separator and header semantics.
Prints JSON: {image_id: {filename, split, K, image_size, camera_size, c2w, near, far}}.
"""
import csv, glob, json, os, sys

import numpy as np
import pycolmap
from PIL import Image

root = sys.argv[1]
with open(glob.glob(os.path.join(root, '*.tsv'))[0], newline='') as f:
    files = list(csv.DictReader(f, delimiter='\t'))

rec = pycolmap.Reconstruction(os.path.join(root, 'dense/sparse'))
img_path_to_id = {v.name: v.image_id for v in rec.images.values()}
img_ids = [img_path_to_id[row['filename']] for row in files]

out = {}
bottom = np.array([0, 0, 0, 1.0]).reshape(1, 4)
xyz_world = np.array([p.xyz for p in rec.points3D.values()])
xyz_world_h = np.concatenate([xyz_world, np.ones((len(xyz_world), 1))], -1)
for row, id_ in zip(files, img_ids):
    im = rec.images[id_]
    cam = rec.cameras[id_]  # nerf_pl: camdata[id_] -- the camera keyed by the IMAGE id
    K = [cam.params[0], cam.params[1], cam.params[2], cam.params[3]]
    cfw = im.cam_from_world()
    R = cfw.rotation.matrix()
    t = np.asarray(cfw.translation).reshape(3, 1)
    w2c = np.concatenate([np.concatenate([R, t], 1), bottom], 0)
    pose = np.linalg.inv(w2c)[:3]
    pose = np.concatenate([pose[..., 1:2], -pose[..., :1], pose[..., 2:4]], -1)
    xyz_cam = (xyz_world_h @ w2c.T)[:, :3]
    xyz_cam = xyz_cam[xyz_cam[:, 2] > 0]
    img = Image.open(os.path.join(root, 'dense/images', row['filename'])).convert('RGB')
    out[str(id_)] = {
        'filename': row['filename'],
        'split': row['split'],
        'id_column': row['id'],
        'dataset': row['dataset'],
        'K': [float(k) for k in K],
        'image_size': list(img.size),
        'camera_size': [cam.width, cam.height],
        'model': str(cam.model),
        'c2w': pose.tolist(),
        'near': float(np.percentile(xyz_cam[:, 2], 0.1)) if len(xyz_cam) else None,
        'far': float(np.percentile(xyz_cam[:, 2], 99.9)) if len(xyz_cam) else None,
        'rgb_sha': __import__('hashlib').sha256(img.tobytes()).hexdigest(),
    }
print(json.dumps(out))
