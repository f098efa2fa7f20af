#!/usr/bin/env python3
"""Projects a COLMAP model's sparse points through an `export --layout nerfstudio` folder's
transforms.json, following nerfstudio's documented conventions (dev-time oracle only).

usage: nerfstudio_projector.py EXPORT_DIR MODEL_DIR
Conventions (docs.nerf.studio "Data conventions", nerfstudio/process_data/colmap_utils.py):
transform_matrix is camera-to-world with OpenGL camera axes (x right, y up, z back) in the
world frame rotated by `applied_transform` (3 x 4, world -> nerfstudio world); per-frame
intrinsics fl_x, fl_y, cx, cy in pixels of a w x h image; OPENCV distortion (k1, k2, p1, p2;
k3 absent = 0) or OPENCV_FISHEYE (k1..k4 on theta = atan(r)).
For every observation of every 3D point in the model (images matched by colmap_im_id), prints
JSON lines: {"image": id, "point": id, "uv": [u, v], "obs": [x, y] (model pixels),
"model_size": [w, h], "frame_size": [w, h]}.
"""
import json, os, sys

import numpy as np
import pycolmap

export, model_dir = sys.argv[1], sys.argv[2]
meta = json.load(open(os.path.join(export, 'transforms.json')))
A = np.eye(4)
A[:3] = np.array(meta['applied_transform'])
rec = pycolmap.Reconstruction(model_dir)


def project(f, xyz):
    c2w = np.array(f['transform_matrix'])
    p = np.linalg.inv(c2w) @ (A @ np.append(xyz, 1.0))
    x, y, z = p[0], -p[1], -p[2]  # OpenGL -> OpenCV camera axes
    if z <= 0:
        return None
    u, v = x / z, y / z
    if f['camera_model'] == 'OPENCV':
        k1, k2, p1, p2 = f['k1'], f['k2'], f['p1'], f['p2']
        k3 = f.get('k3', 0.0)
        r2 = u * u + v * v
        radial = k1 * r2 + k2 * r2 * r2 + k3 * r2 ** 3
        du = u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u)
        dv = v * radial + 2 * p2 * u * v + p1 * (r2 + 2 * v * v)
        u, v = u + du, v + dv
    elif f['camera_model'] == 'OPENCV_FISHEYE':
        r = np.hypot(u, v)
        if r > 1e-12:
            th = np.arctan(r)
            t2 = th * th
            thd = th * (1 + f['k1'] * t2 + f['k2'] * t2 ** 2 + f['k3'] * t2 ** 3 + f['k4'] * t2 ** 4)
            u, v = u * thd / r, v * thd / r
    else:
        raise SystemExit('unknown camera_model ' + f['camera_model'])
    return [f['fl_x'] * u + f['cx'], f['fl_y'] * v + f['cy']]


for f in meta['frames']:
    im = rec.images[f['colmap_im_id']]
    cam = rec.cameras[im.camera_id]
    for p2d in im.points2D:
        if not p2d.has_point3D():
            continue
        uv = project(f, rec.points3D[p2d.point3D_id].xyz)
        print(json.dumps({
            'image': im.image_id, 'point': int(p2d.point3D_id), 'uv': uv,
            'obs': [float(p2d.xy[0]), float(p2d.xy[1])],
            'model_size': [cam.width, cam.height], 'frame_size': [f['w'], f['h']],
        }))
