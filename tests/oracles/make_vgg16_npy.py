#!/usr/bin/env python3
"""Write a `vgg16.npy` in tensorflow-vgg's layout (the file the published code's VGG reads)
from torchvision VGG16 weights in safetensors, for tests: a NumPy object array holding the
dict {'conv1_1': [W, b], ...}, W as (3, 3, in, out) float32 and conv1_1's input channels in
BGR order. The values are ImageNet torchvision weights, not Caffe's: the tests compare our
official tier with the published code given the *same* file, so what matters is the layout.

usage: make_vgg16_npy.py WEIGHTS.safetensors OUT.npy
"""
import json
import struct
import sys

import numpy as np

# torchvision `features` index of each VGG16 convolution, in tensorflow-vgg's names.
CONVS = [(0, 'conv1_1'), (2, 'conv1_2'), (5, 'conv2_1'), (7, 'conv2_2'), (10, 'conv3_1'),
         (12, 'conv3_2'), (14, 'conv3_3'), (17, 'conv4_1'), (19, 'conv4_2'), (21, 'conv4_3'),
         (24, 'conv5_1'), (26, 'conv5_2'), (28, 'conv5_3')]


def safetensors(path):
    raw = open(path, 'rb').read()
    (n,) = struct.unpack('<Q', raw[:8])
    header = json.loads(raw[8:8 + n])
    out = {}
    for name, t in header.items():
        if name == '__metadata__':
            continue
        assert t['dtype'] == 'F32', (name, t['dtype'])
        a, b = t['data_offsets']
        out[name] = np.frombuffer(raw[8 + n + a:8 + n + b], '<f4').reshape(t['shape'])
    return out


def main(src, dst):
    st = safetensors(src)
    layers = {}
    for idx, name in CONVS:
        w = st['features.%d.weight' % idx]  # (out, in, kh, kw), RGB input for conv1_1
        if name == 'conv1_1':
            w = w[:, ::-1]  # tensorflow-vgg's conv1_1 reads BGR
        layers[name] = [np.ascontiguousarray(w.transpose(2, 3, 1, 0)).astype(np.float32),
                        st['features.%d.bias' % idx].astype(np.float32)]
    np.save(dst, layers)


if __name__ == '__main__':
    main(*sys.argv[1:3])
