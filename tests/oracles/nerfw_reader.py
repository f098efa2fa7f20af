#!/usr/bin/env python3
"""Reads an `export --layout nerfw` folder the way NeRF-W loaders do (dev-time oracle only).

usage: nerfw_reader.py EXPORT_DIR [IMG_DOWNSCALE]
A transcription of kwea123/nerf_pl's final Phototourism loader (branch `nerfw`,
datasets/phototourism.py, PhototourismDataset.read_meta with use_cache=False), which Ha-NeRF
copies. It is transcribed rather than run because the original imports torch and torchvision
at module level (about 3 GB of wheels, never installed in CI); the lines below follow it in
order, each step marked with the loader's own step number:
  tsv:    the first *.tsv, read tab-separated with a header; rows whose id is null dropped
          (`self.files[~self.files['id'].isnull()]`) and the index reset;
  step 1: image ids by name from dense/sparse/images.bin (the tsv's id column is not used);
  step 2: K from camdata[image_id].params[0:4], rescaled with img_w, img_h = int(cx*2),
          int(cy*2): the loader assumes the principal point is the image centre;
  step 3: c2w = inv(w2c)[:3], then `poses[..., 1:3] *= -1` ("right down front" -> "right up
          back");
  step 4: near/far per image as the 0.1 and 99.9 percentiles of the depths of the points3D in
          front of it; every pose translation, near and far divided by max(far) / 5;
  step 5: train/test lists from the tsv's split column, in tsv order.
The model is read with pycolmap instead of nerf_pl's copy of COLMAP's read_write_model.py
(the same binary format); pandas' null test is the same on this file as an empty or NaN
field. Each image is opened from dense/images/filename as the loader opens it.
Prints JSON: {'images': {image_id: {...}}, 'scale_factor': s, 'train': [...], 'test': [...]}.
"""
import csv, glob, hashlib, json, math, os, sys

import numpy as np
import pycolmap
from PIL import Image

root = sys.argv[1]
img_downscale = int(sys.argv[2]) if len(sys.argv) > 2 else 1
tsv = glob.glob(os.path.join(root, '*.tsv'))[0]
with open(tsv, newline='') as f:
    files = list(csv.DictReader(f, delimiter='\t'))


def isnull(v):
    return v is None or v.strip() == '' or (v.strip().lower() == 'nan')


files = [row for row in files if not isnull(row['id'])]  # remove data without id

# Step 1. load image paths
rec = pycolmap.Reconstruction(os.path.join(root, 'dense/sparse'))
img_path_to_id = {v.name: v.image_id for v in rec.images.values()}
img_ids = [img_path_to_id[row['filename']] for row in files]

# Step 2: read and rescale camera intrinsics
Ks, wh_from_k = {}, {}
for id_ in img_ids:
    cam = rec.cameras[id_]  # camdata[id_]: the camera keyed by the IMAGE id
    p = cam.params
    img_w, img_h = int(p[2] * 2), int(p[3] * 2)
    img_w_, img_h_ = img_w // img_downscale, img_h // img_downscale
    Ks[id_] = [p[0] * img_w_ / img_w, p[1] * img_h_ / img_h,
               p[2] * img_w_ / img_w, p[3] * img_h_ / img_h]
    wh_from_k[id_] = [img_w, img_h]

# Step 3: read c2w poses (of the images in tsv file only) and correct the order
bottom = np.array([0, 0, 0, 1.0]).reshape(1, 4)
w2c_mats = []
for id_ in img_ids:
    cfw = rec.images[id_].cam_from_world()
    R = cfw.rotation.matrix()
    t = np.asarray(cfw.translation).reshape(3, 1)
    w2c_mats += [np.concatenate([np.concatenate([R, t], 1), bottom], 0)]
w2c_mats = np.stack(w2c_mats, 0)
poses = np.linalg.inv(w2c_mats)[:, :3]
poses[..., 1:3] *= -1

# Step 4: correct scale
xyz_world = np.array([p.xyz for p in rec.points3D.values()])
xyz_world_h = np.concatenate([xyz_world, np.ones((len(xyz_world), 1))], -1)
nears, fars = {}, {}
for i, id_ in enumerate(img_ids):
    xyz_cam_i = (xyz_world_h @ w2c_mats[i].T)[:, :3]
    xyz_cam_i = xyz_cam_i[xyz_cam_i[:, 2] > 0]
    nears[id_] = np.percentile(xyz_cam_i[:, 2], 0.1)
    fars[id_] = np.percentile(xyz_cam_i[:, 2], 99.9)
max_far = np.fromiter(fars.values(), np.float32).max()
scale_factor = max_far / 5
poses[..., 3] /= scale_factor
for k in nears:
    nears[k] /= scale_factor
for k in fars:
    fars[k] /= scale_factor

# Step 5. split the img_ids
train = [id_ for i, id_ in enumerate(img_ids) if files[i]['split'] == 'train']
test = [id_ for i, id_ in enumerate(img_ids) if files[i]['split'] == 'test']

out = {}
for i, (row, id_) in enumerate(zip(files, img_ids)):
    cam = rec.cameras[id_]
    img = Image.open(os.path.join(root, 'dense/images', row['filename'])).convert('RGB')
    out[str(id_)] = {
        'filename': row['filename'],
        'split': row['split'],
        'id_column': row['id'],
        'dataset': row['dataset'],
        'K': [float(k) for k in Ks[id_]],
        'img_wh_from_cx_cy': wh_from_k[id_],
        'image_size': list(img.size),
        'camera_size': [cam.width, cam.height],
        'model': str(cam.model),
        'c2w': poses[i].tolist(),
        'near': float(nears[id_]),
        'far': float(fars[id_]),
        'rgb_sha': hashlib.sha256(img.tobytes()).hexdigest(),
    }
print(json.dumps({'images': out, 'scale_factor': float(scale_factor), 'train': train,
                  'test': test}))
