#!/usr/bin/env python3
"""The published code's TFRecord path, transcribed without TensorFlow for the benchmark:
dataset_utils.AlignedRenderedDataset (cv2.imread of the official PNGs, channel reorders,
.tostring()) -> _to_example -> TFRecordWriter, for train/ and val/. The Example is encoded by
hand and framed with the crc32c package (C), so the cost is what the published loop pays for
decoding and copying, not a slow Python CRC.

usage: tfrecord_python.py OFFICIAL_DIR OUT_DIR NAME  -> prints {"views": n, "seconds": s}
"""
import glob, os, struct, sys, time

import crc32c
import cv2
import numpy as np


def varint(v):
    out = bytearray()
    while v >= 0x80:
        out.append((v & 0x7F) | 0x80)
        v >>= 7
    out.append(v)
    return bytes(out)


def field(num, payload):
    return varint(num << 3 | 2) + varint(len(payload)) + payload


def to_example(d):
    feats = b''
    for k, v in d.items():
        if isinstance(v, int):
            value = field(3, field(1, varint(v)))
        else:
            value = field(1, field(1, v))
        feats += field(1, field(1, k.encode()) + field(2, value))
    return field(1, feats)


def masked(c):
    return (((c >> 15) | (c << 17)) + 0xA282EAD8) & 0xFFFFFFFF


def write_record(f, data):
    header = struct.pack('<Q', len(data))
    f.write(header + struct.pack('<I', masked(crc32c.crc32c(header))))
    f.write(data + struct.pack('<I', masked(crc32c.crc32c(data))))


def aligned(pattern):
    for rendered in sorted(glob.glob(pattern)):
        base = rendered[:-9]
        img_rendered = cv2.imread(rendered, cv2.IMREAD_UNCHANGED)[:, :, [2, 1, 0, 3]]
        img_depth = cv2.imread(base + 'depth.png', cv2.IMREAD_UNCHANGED).astype(np.uint16)
        img_ref = cv2.imread(base + 'reference.png')[:, :, ::-1]
        img_seg = cv2.imread(base + 'seg_rgb.png')[:, :, ::-1]
        yield {'height': img_ref.shape[0], 'width': img_ref.shape[1],
               'rendered': img_rendered.tobytes(), 'depth': img_depth.tobytes(),
               'real': img_ref.tobytes(), 'seg': img_seg.tobytes()}


def main():
    src, out, name = sys.argv[1:4]
    os.makedirs(out, exist_ok=True)
    t = time.perf_counter()
    n = 0
    for split in ('train', 'val'):
        with open(os.path.join(out, '%s_%s.tfrecord' % (name, split)), 'wb') as f:
            for case in aligned(os.path.join(src, split, '*_color.png')):
                write_record(f, to_example(case))
                n += 1
    print('{"views": %d, "seconds": %f}' % (n, time.perf_counter() - t))


if __name__ == '__main__':
    main()
