#!/usr/bin/env python3
"""An independent reader of `nrw-etl export --layout official|tfrecord`, as the paper's
published code (google/neural_rerendering_in_the_wild) reads it. The lines that define the
format are transcribed from that code (dataset_utils.AlignedRenderedDataset,
data._parser_rendered_dataset, segment_dataset.get_semantic_color_coding,
utils.get_central_crop, style_loss.compute_pairwise_style_loss_v2,
pretrain_appearance.get_triplet_input_fn); TensorFlow itself is not needed: TFRecord framing,
CRC-32C and the Example protobuf are decoded here by hand. Pillow stands in for cv2.imread.

usage: official_reader.py [--official DIR] [--tfrecord DIR --name NAME] [--dataset DATASET]
Prints a JSON summary; exits non-zero (an AssertionError) on any departure.
"""
import argparse, glob, json, os, pickle, struct, sys

import numpy as np
from PIL import Image

# segment_dataset.get_semantic_color_coding(): 29 Cityscapes colours, the last one for every
# class not chosen.
COLORS = [(111, 74, 0), (81, 0, 81), (128, 64, 128), (244, 35, 232), (250, 170, 160),
          (230, 150, 140), (70, 70, 70), (102, 102, 156), (190, 153, 153), (180, 165, 180),
          (150, 100, 100), (150, 120, 90), (153, 153, 153), (250, 170, 30), (220, 220, 0),
          (107, 142, 35), (152, 251, 152), (70, 130, 180), (220, 20, 60), (255, 0, 0),
          (0, 0, 142), (0, 0, 70), (0, 60, 100), (0, 0, 90), (0, 0, 110), (0, 80, 100),
          (0, 0, 230), (119, 11, 32), (0, 0, 142)]
CHOSEN = {1: 0, 2: 1, 3: 2, 105: 3, 27: 4, 60: 5, 5: 6, 12: 7, 4: 7, 7: 7, 13: 8, 18: 9,
          17: 10, 20: 11, 6: 12, 22: 13, 35: 14, 14: 15, 10: 16, 70: 17, 54: 18, 101: 19,
          77: 20, 85: 21, 23: 22, 88: 23, 43: 24, 9: 25, 15: 26, 133: 27}
ID_TO_RGB = np.array([COLORS[CHOSEN.get(i, -1)] for i in range(151)], dtype=np.uint8)
OFFICIAL_SET = {tuple(c) for c in COLORS}
FEATURES = ['height', 'width', 'rendered', 'depth', 'real', 'seg']


def get_central_crop(img, crop_height=512, crop_width=512):
    if len(img.shape) == 2:
        img = np.expand_dims(img, axis=2)
    height, width, _ = img.shape
    assert height >= crop_height and width >= crop_width
    st_y = (height - crop_height) // 2
    st_x = (width - crop_width) // 2
    return np.squeeze(img[st_y:st_y + crop_height, st_x:st_x + crop_width, :])


def aligned_rendered_dataset(pattern, use_semantic_map=True):
    """dataset_utils.AlignedRenderedDataset, yielding arrays instead of .tostring()."""
    filenames = sorted(glob.glob(pattern))
    assert len(filenames) > 0, 'input %s didn\'t match any files!' % pattern
    for rendered_img_name in filenames:
        basename = rendered_img_name[:-9]  # remove the 'color.png' suffix
        img_rendered = np.array(Image.open(rendered_img_name))  # RGBA (cv2 BGRA reordered)
        img_depth = np.array(Image.open(basename + 'depth.png')).astype(np.uint16)
        img_ref = np.array(Image.open(basename + 'reference.png'))
        img_seg = None
        if use_semantic_map:
            img_seg = np.array(Image.open(basename + 'seg_rgb.png'))
            if img_seg.shape[0] == 512 and img_seg.shape[1] == 512:
                img_ref = get_central_crop(img_ref)
                img_rendered = get_central_crop(img_rendered)
                img_depth = get_central_crop(img_depth)
            assert img_seg.shape == img_depth.shape + (3,), basename
        assert img_ref.shape == img_depth.shape + (3,), basename
        assert img_rendered.shape == img_depth.shape + (4,), basename
        assert len(img_depth.shape) == 2, basename
        yield dict(name=os.path.basename(basename), height=img_ref.shape[0],
                   width=img_ref.shape[1], rendered=img_rendered, depth=img_depth,
                   real=img_ref, seg=img_seg)


def parse_like_data_py(ex, use_semantics=True):
    """data._parser_rendered_dataset's scaling (use_alpha, use_depth, use_semantics): the
    conditional input and the real image as float32 in what should be [-1, 1]."""
    h, w = ex['height'], ex['width']
    rendered = np.frombuffer(ex['rendered'], np.uint8).astype(np.float32) * (2.0 / 255) - 1.0
    parts = [rendered.reshape(h, w, 4)]
    depth = np.frombuffer(ex['depth'], np.uint16).reshape(h, w, 1)
    parts.append(depth.astype(np.float32) * (2.0 / 255) - 1.0)
    if use_semantics:
        seg = np.frombuffer(ex['seg'], np.uint8).reshape(h, w, 3)
        parts.append(seg.astype(np.float32) * (2.0 / 255) - 1)
    real = np.frombuffer(ex['real'], np.uint8).astype(np.float32) * (2.0 / 255) - 1.0
    return np.concatenate(parts, axis=-1), real.reshape(h, w, 3)


def crc32c(data, _table=[]):
    if not _table:
        for i in range(256):
            c = i
            for _ in range(8):
                c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
            _table.append(c)
    crc = 0xFFFFFFFF
    for b in data:
        crc = _table[(crc ^ b) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


def masked(crc):
    return (((crc >> 15) | (crc << 17)) + 0xA282EAD8) & 0xFFFFFFFF


def tfrecords(path):
    """Records of a TFRecord file, every length and data CRC checked."""
    with open(path, 'rb') as f:
        buf = f.read()
    at = 0
    while at < len(buf):
        header = buf[at:at + 8]
        (length,) = struct.unpack('<Q', header)
        (lcrc,) = struct.unpack('<I', buf[at + 8:at + 12])
        assert lcrc == masked(crc32c(header)), '%s: length CRC at byte %d' % (path, at)
        data = buf[at + 12:at + 12 + length]
        (dcrc,) = struct.unpack('<I', buf[at + 12 + length:at + 16 + length])
        assert dcrc == masked(crc32c(data)), '%s: data CRC at byte %d' % (path, at)
        yield data
        at += 16 + length


def varint(b, at):
    v, shift = 0, 0
    while True:
        x = b[at]
        at += 1
        v |= (x & 0x7F) << shift
        shift += 7
        if x < 0x80:
            return v, at


def fields(b):
    """(field number, wire type, value) of a protobuf message."""
    at = 0
    while at < len(b):
        key, at = varint(b, at)
        num, wt = key >> 3, key & 7
        if wt == 2:
            n, at = varint(b, at)
            yield num, wt, b[at:at + n]
            at += n
        elif wt == 0:
            v, at = varint(b, at)
            yield num, wt, v
        else:
            raise AssertionError('unexpected wire type %d' % wt)


def parse_example(data):
    """tf.train.Example -> {key: int or bytes}, checking the types FixedLenFeature asks for."""
    out = {}
    (num, wt, features), = list(fields(data))
    assert num == 1 and wt == 2, 'Example.features'
    for num, _, entry in fields(features):
        assert num == 1, 'Features.feature'
        kv = {n: v for n, _, v in fields(entry)}
        key = kv[1].decode()
        (kind, _, lst), = list(fields(kv[2]))
        values = [v for n, _, v in fields(lst)]
        if kind == 3:  # int64_list, packed
            (packed,) = values
            v, at = varint(packed, 0)
            assert at == len(packed), key
            out[key] = v
        elif kind == 1:  # bytes_list
            (out[key],) = values
        else:
            raise AssertionError('%s: feature kind %d' % (key, kind))
    return out


def check_official(root, use_semantic):
    summary = {}
    views = {}
    for split in sorted(d for d in os.listdir(root) if os.path.isdir(os.path.join(root, d))):
        items = list(aligned_rendered_dataset(os.path.join(root, split, '*_color.png'),
                                              use_semantic))
        names = [it['name'] for it in items]
        assert [int(n.rstrip('_')) for n in names] == list(range(len(items))), \
            '%s: names sort in index order: %s' % (split, names[:5])
        for it in items:
            ex = dict(height=it['height'], width=it['width'], rendered=it['rendered'].tobytes(),
                      depth=it['depth'].tobytes(), real=it['real'].tobytes(),
                      seg=it['seg'].tobytes() if use_semantic else b'')
            cond, real = parse_like_data_py(ex, use_semantic)
            assert cond.shape[-1] == (8 if use_semantic else 5)  # alpha, depth, seg channels
            assert cond.min() >= -1.0 and cond.max() <= 1.0, '%s: channel out of [-1, 1]' % it['name']
            assert real.min() >= -1.0 and real.max() <= 1.0
            if use_semantic:
                colours = {tuple(c) for c in it['seg'].reshape(-1, 3)}
                assert colours <= OFFICIAL_SET, '%s: colours %s' % (it['name'], colours - OFFICIAL_SET)
        views[split] = items
        summary[split] = len(items)
    return summary, views


def check_tfrecord(root, name, official_views):
    summary = {}
    for split in ('train', 'val'):
        files = sorted(glob.glob(os.path.join(root, name + '*_%s.tfrecord' % split)))
        if not files:
            continue
        n = 0
        for f in files:
            for rec in tfrecords(f):
                ex = parse_example(rec)
                assert sorted(ex) == sorted(FEATURES), sorted(ex)
                h, w = ex['height'], ex['width']
                assert isinstance(h, int) and isinstance(w, int)
                assert len(ex['rendered']) == h * w * 4 and len(ex['real']) == h * w * 3
                assert len(ex['depth']) == h * w * 2, 'depth is uint16'
                assert len(ex['seg']) in (h * w * 3, 0)
                use_sem = len(ex['seg']) > 0
                cond, real = parse_like_data_py(ex, use_sem)
                assert cond.min() >= -1.0 and cond.max() <= 1.0
                if use_sem:
                    seg = np.frombuffer(ex['seg'], np.uint8).reshape(-1, 3)
                    assert {tuple(c) for c in seg} <= OFFICIAL_SET
                if official_views is not None:
                    v = official_views[split][n]
                    assert (h, w) == (v['height'], v['width'])
                    assert ex['rendered'] == v['rendered'].tobytes(), 'rendered = color.png'
                    assert ex['real'] == v['real'].tobytes(), 'real = reference.png'
                    assert ex['depth'] == v['depth'].astype('<u2').tobytes(), 'depth = depth.png'
                    if use_sem:
                        assert ex['seg'] == v['seg'].tobytes(), 'seg = seg_rgb.png'
                n += 1
        if official_views is not None:
            assert n == len(official_views[split]), (split, n, len(official_views[split]))
        summary[split] = n
    return summary


def official_grams(descriptor):
    """Undo the packing of our official descriptor: per layer (C = 64 ... 512) the upper
    triangle of G / C with off-diagonals times sqrt(2)."""
    grams, at = [], 0
    d = np.asarray(descriptor, dtype=np.float64)
    for c in (64, 128, 256, 512, 512):
        iu = np.triu_indices(c)
        m = c * (c + 1) // 2
        packed = d[at:at + m] * c
        at += m
        g = np.zeros((c, c))
        g[iu] = packed
        off = iu[0] != iu[1]
        g[iu[0][off], iu[1][off]] /= np.sqrt(2.0)
        g = np.triu(g) + np.triu(g, 1).T
        grams.append(g[None])  # batch of 1, as sess.run returns it
    assert at == len(d), 'descriptor length %d, expected %d' % (len(d), at)
    return grams


def check_pickle(root, dataset, name):
    import pyarrow.parquet as pq
    meta = json.load(open(os.path.join(root, 'export.json')))
    path = os.path.join(root, 'dist_%s.pckl' % name)
    with open(path, 'rb') as f:
        dist_matrix = pickle.load(f)['dist_matrix']
    filenames = sorted(glob.glob(os.path.join(root, 'train', '*_reference.png')))
    n = len(filenames)
    assert dist_matrix.dtype == np.float64 and dist_matrix.shape == (n, n)
    assert np.array_equal(dist_matrix, dist_matrix.T) and not np.diag(dist_matrix).any()
    train = [s for s in meta['splits'] if s['split'] == 'train'][0]
    assert len(train['image_ids']) == n
    table = pq.read_table(os.path.join(dataset, 'descriptors'))
    rows = {i: d for i, d in zip(table.column('image_id').to_pylist(),
                                 table.column('descriptor').to_pylist())}
    assert set(table.column('tier').to_pylist()) <= {'official'} or \
        all(t.startswith('official') for t in table.column('tier').to_pylist())
    # Row k of the matrix is the k-th sorted *_reference.png = image_ids[k] (export.json).
    grams_all = [official_grams(rows[i]) for i in train['image_ids']]
    # style_loss.compute_pairwise_style_loss_v2's double loop.
    expect = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            loss_style = 0
            for gram_i, gram_j in zip(grams_all[i], grams_all[j]):
                loss_style += np.mean((gram_i - gram_j) ** 2, axis=(1, 2))
            expect[i][j] = expect[j][i] = loss_style[0]
    off = ~np.eye(n, dtype=bool)
    rel = np.abs(dist_matrix - expect)[off] / np.abs(expect)[off]
    worst = float(rel.max()) if rel.size else 0.0
    assert worst <= 1e-9, 'worst relative difference %g' % worst
    # pretrain_appearance.get_triplet_input_fn sorts each row: the anchor is its own nearest.
    for ii in range(n):
        assert np.argsort(dist_matrix[ii, :])[0] == ii or dist_matrix[ii].min() == 0
    return {'n': n, 'worst_relative': worst}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--official')
    ap.add_argument('--tfrecord')
    ap.add_argument('--name')
    ap.add_argument('--dataset')
    ap.add_argument('--no-semantics', action='store_true')
    a = ap.parse_args()
    out = {}
    views = None
    if a.official:
        out['official'], views = check_official(a.official, not a.no_semantics)
        if a.dataset:
            out['pickle'] = check_pickle(a.official, a.dataset, a.name)
    if a.tfrecord:
        out['tfrecord'] = check_tfrecord(a.tfrecord, a.name, views)
    json.dump(out, sys.stdout)


if __name__ == '__main__':
    main()
