#!/usr/bin/env python3
"""A float64 VGG16 (numpy, im2col) as an independent oracle for the `official` style tier.

usage: vgg_f64.py WEIGHTS FIXTURE_DIR STEM CROP OURS.f32
1. Checks itself against the PyTorch float64 fixture (STEM.safetensors: the fixture's own
   input through torchvision's VGG16, Grams of relu1_2 ... relu5_2).
2. Computes the published code's style Grams of STEM.png (style_loss.compute_pairwise_
   style_loss_v2: CROP x CROP centre crop by utils.get_central_crop, img * 2/255 - 1 in float32;
   its VGG's (x + 1) * 255 / 2 minus the Caffe means, in float32, channels kept RGB here as the
   weights are; G = F^T F / (C H W)) and compares our official descriptor (OURS.f32:
   little-endian f32, per layer the upper triangle of G / C, off-diagonals times sqrt(2)),
   which ran the same weights read from tensorflow-vgg's vgg16.npy layout (BGR conv1_1).
Prints JSON: worst relative difference (max |a - b| / max |b|) per layer for both checks.
"""
import json, struct, sys

import numpy as np
from PIL import Image

CONVS = [0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26]  # features.N of conv1_1 ... conv5_2
POOL_AFTER = {2, 7, 14, 21}  # max-pool 2x2 after conv1_2, conv2_2, conv3_3, conv4_3
STYLE = {2: 'relu1_2', 7: 'relu2_2', 12: 'relu3_2', 19: 'relu4_2', 26: 'relu5_2'}


def safetensors(path):
    with open(path, 'rb') as f:
        raw = f.read()
    (n,) = struct.unpack('<Q', raw[:8])
    header = json.loads(raw[8:8 + n])
    out = {}
    for k, v in header.items():
        if k == '__metadata__':
            continue
        dt = {'F32': '<f4', 'F64': '<f8'}[v['dtype']]
        a, b = v['data_offsets']
        out[k] = np.frombuffer(raw[8 + n + a:8 + n + b], dtype=dt).reshape(v['shape'])
    return out


def conv3x3_relu(x, w, b):
    c, h, wd = x.shape
    p = np.pad(x, ((0, 0), (1, 1), (1, 1)))
    cols = np.lib.stride_tricks.sliding_window_view(p, (3, 3), axis=(1, 2))  # c, h, w, 3, 3
    cols = cols.transpose(1, 2, 0, 3, 4).reshape(h * wd, c * 9)
    y = cols @ w.reshape(w.shape[0], -1).astype(np.float64).T + b.astype(np.float64)
    return np.maximum(y, 0).T.reshape(w.shape[0], h, wd)


def grams(weights, x):
    out = {}
    for idx in CONVS:
        x = conv3x3_relu(x, weights['features.%d.weight' % idx], weights['features.%d.bias' % idx])
        if idx in STYLE:
            c, h, w = x.shape
            f = x.reshape(c, h * w)
            out[STYLE[idx]] = f @ f.T / (c * h * w)
        if idx in POOL_AFTER:
            c, h, w = x.shape
            x = x[:, :h // 2 * 2, :w // 2 * 2].reshape(c, h // 2, 2, w // 2, 2).max(axis=(2, 4))
    return out


def worst(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


def main():
    weights_path, fixture_dir, stem, crop, ours_path = sys.argv[1:6]
    crop = int(crop)
    weights = safetensors(weights_path)
    fx = safetensors('%s/%s.safetensors' % (fixture_dir, stem))
    mine = grams(weights, fx['input'][0].astype(np.float64))
    self_check = {k: worst(mine[k], fx['gram_' + k]) for k in mine}
    # The published code's input: float32 image, * 2/255 - 1, central crop.
    img = np.array(Image.open('%s/%s.png' % (fixture_dir, stem)).convert('RGB'), dtype=np.float32)
    img = img * 2. / 255. - 1
    h, w, _ = img.shape
    st_y, st_x = (h - crop) // 2, (w - crop) // 2
    img = img[st_y:st_y + crop, st_x:st_x + crop, :]
    # The published VGG's input step (vgg16.py, as ../shared/paper-code/README.md describes it).
    img = (img + np.float32(1)) * np.float32(255.0) / np.float32(2.0)
    img = img - np.array([123.68, 116.779, 103.939], dtype=np.float32)  # R, G, B Caffe means
    ref = grams(weights, img.transpose(2, 0, 1).astype(np.float64))
    d = np.fromfile(ours_path, dtype='<f4').astype(np.float64)
    at, official = 0, {}
    for name in ['relu1_2', 'relu2_2', 'relu3_2', 'relu4_2', 'relu5_2']:
        c = ref[name].shape[0]
        iu = np.triu_indices(c)
        m = c * (c + 1) // 2
        packed = d[at:at + m] * c
        at += m
        scale = np.where(iu[0] == iu[1], 1.0, np.sqrt(2.0))
        g = np.zeros((c, c))
        g[iu] = packed / scale
        g = np.triu(g) + np.triu(g, 1).T
        official[name] = worst(g, ref[name])
    assert at == len(d), (at, len(d))
    json.dump({'self_check_vs_pytorch': self_check, 'official_vs_f64': official}, sys.stdout)


if __name__ == '__main__':
    main()
