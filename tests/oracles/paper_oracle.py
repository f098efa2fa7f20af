#!/usr/bin/env python3
"""Run the paper's published code on our `official` export: the oracle of that format.

The published files (google/neural_rerendering_in_the_wild, in ../shared/paper-code) are
loaded unmodified but for the three load-time patches their README lists for TensorFlow 2 and
NumPy 2 (PATCHES below); nothing of them is transcribed here. What runs:

- `dataset_utils.AlignedRenderedDataset` -> `_generate_tfrecord_dataset` on every split, then
  `data._parser_rendered_dataset` on each record (what the trainer sees); with --tfrecord, our
  own TFRecords parse to the same tensors;
- `pretrain_appearance.read_single_appearance_input` on every reference, at --resolution
  (`--train_resolution`);
- `segment_dataset.get_semantic_color_coding()` applied to the dataset's stored labels, cropped
  by `utils.get_central_crop`: every `*_seg_rgb.png` pixel must equal it;
- `pretrain_appearance.get_triplet_input_fn` with our `dist_NAME.pckl`, every anchor;
- with --npy: `pretrain_appearance.compute_dist_matrix` (hence
  `style_loss.compute_pairwise_style_loss_v2`) on the exported train references, with the
  `vgg16` module below, compared with our pickle.

`style_loss.py` imports `vgg16` from MoustafaMeshry/vgg_loss, which is not redistributable;
the module below is written from the description in ../shared/paper-code/README.md (input
in [-1, 1] -> (x + 1) * 255 / 2, RGB -> BGR minus the Caffe means, tensorflow-vgg's VGG16 conv
layers with ReLU, 2x2 "SAME" max pools, weights from vgg16.npy).

usage: paper_oracle.py --paper DIR --official DIR --dataset DATASET --name NAME
                       --resolution N [--tfrecord DIR] [--npy vgg16.npy] [--out-dist F]
Prints one JSON object; any departure is an AssertionError (non-zero exit).
"""
import argparse
import glob
import io
import json
import os
import sys
import tempfile
import types

import numpy as np

# ../shared/paper-code/README.md: the load-time patches, nothing else.
PATCHES = [
    ('import tensorflow as tf',
     'import tensorflow.compat.v1 as tf\ntf.disable_v2_behavior()'),
    ('.tostring()', '.tobytes()'),
]
STYLE_PATCH = ('dist_matrix[i][j] = dist_matrix[j][i] = loss_style',
               'dist_matrix[i][j] = dist_matrix[j][i] = loss_style.item()')


def load(paper, name):
    """Import a published module by name with the README's patches applied to its text."""
    path = os.path.join(paper, name + '.py')
    src = open(path).read()
    patches = PATCHES + ([STYLE_PATCH] if name == 'style_loss' else [])
    for old, new in patches:
        if old == STYLE_PATCH[0]:
            assert src.count(old) == 1, 'style_loss.py changed: %s' % old
        src = src.replace(old, new)
    mod = types.ModuleType(name)
    mod.__file__ = path
    sys.modules[name] = mod
    exec(compile(src, path, 'exec'), mod.__dict__)
    return mod


def vgg16_module():
    """The `vgg16` module style_loss.py imports, from the published VGG's description."""
    import tensorflow.compat.v1 as tf
    mod = types.ModuleType('vgg16')
    vgg_mean = [103.939, 116.779, 123.68]  # B, G, R

    class Vgg16(object):
        def __init__(self, vgg16_npy_path):
            self.data_dict = np.load(vgg16_npy_path, encoding='latin1',
                                     allow_pickle=True).item()

        def get_vgg_activations(self, rgb, layers):
            rgb_scaled = (rgb + 1) * 255.0 / 2.0
            red, green, blue = tf.split(axis=3, num_or_size_splits=3, value=rgb_scaled)
            x = tf.concat(axis=3, values=[blue - vgg_mean[0], green - vgg_mean[1],
                                          red - vgg_mean[2]])
            acts = {}
            for block, n in enumerate([2, 2, 3, 3, 3], 1):
                for i in range(1, n + 1):
                    name = 'conv%d_%d' % (block, i)
                    w, b = self.data_dict[name]
                    x = tf.nn.conv2d(x, tf.constant(w), [1, 1, 1, 1], padding='SAME')
                    x = tf.nn.relu(tf.nn.bias_add(x, tf.constant(b)))
                    acts[name] = x
                x = tf.nn.max_pool(x, ksize=[1, 2, 2, 1], strides=[1, 2, 2, 1], padding='SAME')
            return [acts[l] for l in layers]

    mod.Vgg16 = Vgg16
    sys.modules['vgg16'] = mod
    return mod


def png(data):
    from PIL import Image
    return np.asarray(Image.open(io.BytesIO(data)))


def stored_labels(dataset):
    """image id -> the dataset's stored ADE20K label map (pyarrow: no Rust involved)."""
    import pyarrow.parquet as pq
    manifest = json.load(open(os.path.join(dataset, 'manifest.json')))
    out = {}
    for t in manifest['tables']:
        if not t['path'].startswith('shards/'):
            continue
        table = pq.read_table(os.path.join(dataset, t['path']),
                              columns=['image_id', 'labels_png'])
        for i, b in zip(table.column('image_id').to_pylist(),
                        table.column('labels_png').to_pylist()):
            out[i] = None if b is None else png(b)
    return out


def parse_records(tf, data, path, use_sem):
    """Every record of a TFRecord file through data._parser_rendered_dataset."""
    ds = tf.data.TFRecordDataset([path]).map(
        lambda s: data._parser_rendered_dataset(
            s, crop_flag=False, crop_size=None, seeds=None, use_alpha=False,
            use_depth=True, use_semantics=use_sem, use_appearance=True))
    nxt = tf.data.make_one_shot_iterator(ds).get_next()
    out = []
    with tf.Session() as sess:
        while True:
            try:
                out.append(sess.run(nxt))
            except tf.errors.OutOfRangeError:
                return out


def check_records(records, resolution, use_sem):
    """Parsed records have every channel in [-1, 1], the published channel counts and size."""
    for k, f in enumerate(records):
        for key in ('conditional_input', 'expected_output', 'peek_input'):
            v = f[key]
            assert v.min() >= -1.0 and v.max() <= 1.0, 'record %d: %s out of [-1, 1]' % (k, key)
        cond = f['conditional_input']
        assert cond.shape[-1] == (7 if use_sem else 4), cond.shape
        if resolution:
            assert cond.shape[:2] == (resolution, resolution), cond.shape
        assert f['peek_input'].shape[-1] == 3 + cond.shape[-1]


def check_split(tf, mods, a, split, labels, ids, tmp):
    """One split through the published converter, parser and pretraining reader."""
    data, dataset_utils = mods[:2]
    use_sem = not a.no_semantics
    out = {}
    parsed = None
    if a.official and use_sem:
        # AlignedRenderedDataset cannot run without semantics (NameError on img_seg).
        it = dataset_utils.AlignedRenderedDataset(os.path.join(a.official, split, '*_color.png'))
        rec = dataset_utils._generate_tfrecord_dataset(it, 'oracle_%s.tfrecord' % split, tmp)
        parsed = parse_records(tf, data, rec, True)
        check_records(parsed, a.resolution, True)
        out['views'] = len(parsed)
    if a.tfrecord:
        files = sorted(glob.glob(os.path.join(a.tfrecord, a.name + '*_%s.tfrecord' % split)))
        ours = [x for fn in files for x in parse_records(tf, data, fn, use_sem)]
        check_records(ours, a.resolution, use_sem)
        out['records'] = len(ours)
        if parsed is not None:
            assert len(ours) == len(parsed), (split, len(ours), len(parsed))
            for k, (x, y) in enumerate(zip(ours, parsed)):
                for key in x:
                    assert np.array_equal(x[key], y[key]), '%s record %d: %s differs' % (
                        split, k, key)
    if ids is not None:
        assert out.get('views', out.get('records')) == len(ids), (split, out, len(ids))
    if a.official and use_sem and a.resolution:
        out['colours'] = check_appearance_inputs(mods, a, split, labels, ids)
    return out


def check_appearance_inputs(mods, a, split, labels, ids):
    """The published pretraining reader on every reference, at the training resolution; the
    seg colours pixel for pixel against the published coding of the stored labels."""
    from PIL import Image
    _, _, pretrain, segment, utils = mods
    refs = sorted(glob.glob(os.path.join(a.official, split, '*_reference.png')))
    assert len(refs) == len(ids)
    colours = segment.get_semantic_color_coding().astype(np.uint8)
    res = a.resolution
    used = set()
    for k, ref in enumerate(refs):
        x = pretrain.read_single_appearance_input(ref)
        assert x.shape == (res, res, 10), (ref, x.shape)
        assert x.min() >= -1.0 and x.max() <= 1.0, ref
        lab = labels[ids[k]]
        assert lab is not None, 'image %d has no labels' % ids[k]
        want = utils.get_central_crop(colours[lab], res, res)
        seg = np.asarray(Image.open(ref[:-len('reference.png')] + 'seg_rgb.png'))
        assert seg.shape == want.shape and np.array_equal(seg, want), \
            '%s: %d pixels differ from the published colour coding' % (
                ref, int((seg != want).any(-1).sum()))
        used |= {tuple(c) for c in seg.reshape(-1, 3)}
    return len(used)


def check_dist(pretrain, root, name, out_dist, npy):
    import pickle
    train = os.path.join(root, 'train')
    dist_path = os.path.join(root, 'dist_%s.pckl' % name)
    ours = pickle.load(open(dist_path, 'rb'))['dist_matrix']
    n = len(glob.glob(os.path.join(train, '*_reference.png')))
    assert ours.shape == (n, n) and ours.dtype == np.float64
    off = ~np.eye(n, dtype=bool)
    dup = [(int(i), int(j)) for i, j in zip(*np.nonzero((ours <= 0) & off)) if i < j]
    assert not dup, 'views at distance 0 (the sampler could pick the anchor): %s' % dup
    # The published sampler, with our pickle, every anchor.
    fn = pretrain.get_triplet_input_fn(train, dist_path)
    np.random.seed(0)
    for a in range(n):
        anchor, pos, neg = fn(a)
        assert anchor.shape == pos.shape == neg.shape, (a, anchor.shape)
        # randint(1, k + 1) never picks index 0 of the sorted row: the anchor itself.
        assert np.argsort(ours[a, :])[0] == a
    out = {'n': n, 'min_off_diagonal': float(ours[off].min()) if n > 1 else None}
    if npy:
        published = pretrain.compute_dist_matrix(train, out_dist, recompute_dist=True)
        rel = np.abs(ours - published)[off] / np.abs(published)[off]
        out['worst_relative'] = float(rel.max()) if rel.size else 0.0
        out['same_order'] = all(
            np.array_equal(np.argsort(ours[i], kind='stable'),
                           np.argsort(published[i], kind='stable')) for i in range(n))
        out['published_example'] = float(published[0, 1]) if n > 1 else None
        out['ours_example'] = float(ours[0, 1]) if n > 1 else None
    return out


def time_published_dist(style_loss, a):
    """compute_pairwise_style_loss_v2 on the exported train references, timed (wall seconds,
    peak resident MB of this process), against our dist_NAME.pckl."""
    import pickle
    import resource
    import time
    refs = sorted(glob.glob(os.path.join(a.official, 'train', '*_reference.png')))
    t = time.perf_counter()
    published = style_loss.compute_pairwise_style_loss_v2(refs)
    seconds = time.perf_counter() - t
    ours = pickle.load(open(os.path.join(a.official, 'dist_%s.pckl' % a.name), 'rb'))['dist_matrix']
    n = len(refs)
    off = ~np.eye(n, dtype=bool)
    rel = np.abs(ours - published)[off] / np.abs(published)[off]
    import tensorflow as tf2
    return {'n': n, 'seconds': seconds,
            'peak_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            'worst_relative': float(rel.max()), 'median_relative': float(np.median(rel)),
            'same_order': all(np.array_equal(np.argsort(ours[i], kind='stable'),
                                             np.argsort(published[i], kind='stable'))
                              for i in range(n)),
            'tensorflow': tf2.__version__}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--paper', required=True)
    ap.add_argument('--official', help='an official export: converted, parsed, read for pretraining')
    ap.add_argument('--tfrecord', help='a tfrecord export: parsed (and compared with --official)')
    ap.add_argument('--dataset', help='the dataset exported: its labels judge the seg colours')
    ap.add_argument('--name', required=True)
    ap.add_argument('--resolution', type=int,
                    help='--train_resolution: also run the pretraining reader and the sampler')
    ap.add_argument('--no-semantics', action='store_true')
    ap.add_argument('--npy', help="tensorflow-vgg's vgg16.npy: recompute the published distance")
    ap.add_argument('--out-dist')
    ap.add_argument('--only-dist', action='store_true',
                    help='benchmark: only the published distance, timed, against our pickle')
    a = ap.parse_args()
    os.environ.setdefault('TF_CPP_MIN_LOG_LEVEL', '2')
    sys.path.insert(0, a.paper)
    import tensorflow.compat.v1 as tf
    tf.disable_v2_behavior()
    vgg16_module()
    mods = {}
    for m in ('options', 'utils', 'layers', 'networks', 'data', 'segment_dataset', 'style_loss',
              'dataset_utils', 'pretrain_appearance'):
        mods[m] = load(a.paper, m)
    from absl import flags
    argv = ['paper', '--train_resolution=%d' % (a.resolution or 256)]
    if a.no_semantics:
        argv += ['--use_semantic=False', '--deep_buffer_nc=4', '--appearance_nc=7']
    if a.npy:
        argv.append('--vgg16_path=%s' % a.npy)
    flags.FLAGS(argv)
    if a.only_dist:
        real_stdout, sys.stdout = sys.stdout, sys.stderr
        try:
            out = time_published_dist(mods['style_loss'], a)
        finally:
            sys.stdout = real_stdout
        json.dump(out, sys.stdout)
        return
    labels = stored_labels(a.dataset) if a.dataset and a.resolution else {}
    meta_dir = a.official or a.tfrecord
    export = json.load(open(os.path.join(meta_dir, 'export.json')))
    out = {'splits': {}}
    # What the published code prints goes to stderr, so stdout stays one JSON object.
    real_stdout, sys.stdout = sys.stdout, sys.stderr
    try:
        with tempfile.TemporaryDirectory() as tmp:
            order = (mods['data'], mods['dataset_utils'], mods['pretrain_appearance'],
                     mods['segment_dataset'], mods['utils'])
            for s in export['splits']:
                out['splits'][s['split']] = check_split(tf, order, a, s['split'], labels,
                                                        s['image_ids'], tmp)
            pickle_path = os.path.join(a.official or '', 'dist_%s.pckl' % a.name)
            if a.official and a.resolution and os.path.exists(pickle_path):
                dist = a.out_dist or os.path.join(tmp, 'published_dist.pckl')
                out['dist'] = check_dist(mods['pretrain_appearance'], a.official, a.name, dist,
                                         a.npy)
    finally:
        sys.stdout = real_stdout
    json.dump(out, sys.stdout)


if __name__ == '__main__':
    main()
