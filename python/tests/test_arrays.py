"""Every array nrw.Dataset gives equals what pyarrow + Pillow + OpenEXR decode from the same
shards; tables equal pyarrow's reads of the same files."""

import gc
import os

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import nrw
import reference

ARRAYS = {"photo": (3, np.uint8), "color": (4, np.uint8), "depth": (None, np.float32),
          "normals": (3, np.uint8), "semantics": (3, np.uint8), "labels": (None, np.uint8),
          "transient": (None, np.uint8)}


def assert_view_equals(view, expected):
    keys = {k for k in view if k in ARRAYS}
    assert keys == {k for k in expected if k in ARRAYS}, (view["image_id"], keys)
    assert {"photo", "color", "depth"} <= keys
    for key in keys:
        got, want = view[key], expected[key]
        channels, dtype = ARRAYS[key]
        assert got.dtype == dtype, (key, got.dtype)
        assert got.shape == want.shape, (key, got.shape, want.shape)
        assert got.shape[2:] == ((channels,) if channels else ()), (key, got.shape)
        np.testing.assert_array_equal(got, want, err_msg=f"image {view['image_id']} {key}")
    assert view["name"] == expected["name"]


def test_every_view_equals_the_pure_python_decode(dataset):
    ds = nrw.Dataset(dataset)
    expected = [reference.decode(r) for r in reference.rows(dataset)]
    views = list(ds.views())
    assert len(views) == len(expected) == len(ds) > 0
    # File order, then each view's arrays.
    assert [v["image_id"] for v in views] == [e["image_id"] for e in expected]
    for view, want in zip(views, expected):
        assert_view_equals(view, want)
    demo = "normals" in views[0]
    if dataset == os.environ.get("NRW_TEST_DEMO"):
        assert demo and "labels" in views[0], "the demo has normals and semantics"


def test_splits_get_and_get_many_follow_the_split_table(dataset):
    ds = nrw.Dataset(dataset)
    by_split = {}
    for image_id, split in reference.splits(dataset).items():
        by_split.setdefault(split, []).append(image_id)
    assert ds.splits() == {k: len(v) for k, v in by_split.items()}
    expected = {r["image_id"]: r for r in reference.rows(dataset)}
    for split, ids in by_split.items():
        assert ds.ids(split) == sorted(ids)
        it = ds.views(split)
        assert len(it) == len(ids)
        next(it)
        assert len(it) == len(ids) - 1
        it = ds.views(split)
        assert sorted(v["image_id"] for v in it) == sorted(ids)
    some = list(expected)[::-2]
    for view, image_id in zip(ds.get_many(some + some[:1]), some + some[:1]):
        assert view["image_id"] == image_id
        assert_view_equals(view, reference.decode(expected[image_id]))
    assert_view_equals(ds.get(some[0]), reference.decode(expected[some[0]]))
    assert some[0] in ds and 4_000_000_000 not in ds
    assert [v["image_id"] for v in ds.views(ids=[some[0], some[0]])] == [some[0]]


def test_triplets_and_descriptors_are_the_files_tables(dataset):
    ds = nrw.Dataset(dataset)
    triplets = ds.triplets()
    assert isinstance(triplets, pa.Table)
    assert triplets.equals(pq.read_table(os.path.join(dataset, "triplets.parquet")))
    # Zero-copy: pyarrow allocates nothing; the buffers are the ones Rust read into. (The
    # collector is held off, so no earlier table is freed in between.)
    gc.collect()
    gc.disable()
    try:
        before = pa.total_allocated_bytes()
        descriptors = ds.descriptors()
        allocated = pa.total_allocated_bytes() - before
    finally:
        gc.enable()
    assert allocated == 0
    parts = sorted(p for p in os.listdir(os.path.join(dataset, "descriptors")) if p.endswith(".parquet"))
    want = pa.concat_tables(pq.read_table(os.path.join(dataset, "descriptors", p)) for p in parts)
    assert descriptors.num_rows == len(ds) > 0
    assert descriptors.equals(want)
    assert descriptors.column("descriptor").type.value_type == pa.float32()


def test_bad_requests_name_what_is_missing(demo, tmp_path):
    ds = nrw.Dataset(demo)
    with pytest.raises(KeyError, match="image 4000000000 is not a kept view"):
        ds.get(4_000_000_000)
    with pytest.raises(KeyError, match="no split \"nope\""):
        ds.views("nope")
    with pytest.raises(ValueError, match="a split or ids, not both"):
        ds.views("train", ids=[1])
    missing = tmp_path / "nowhere"
    with pytest.raises(nrw.DatasetError, match=str(missing)):
        nrw.Dataset(missing)


def test_the_old_render_key_warns_and_reads_the_color_array(demo):
    import pickle

    view = nrw.Dataset(demo).get(nrw.Dataset(demo).ids()[0])
    assert "color" in view and "render" not in view, sorted(view)
    with pytest.warns(DeprecationWarning, match=r"view\['render'\] is now view\['color'\]"):
        old = view["render"]
    assert old is view["color"]
    with pytest.raises(KeyError, match="rendr"):
        view["rendr"]
    # A view pickles (DataLoader workers send it) and keeps the alias.
    back = pickle.loads(pickle.dumps(view))
    with pytest.warns(DeprecationWarning):
        np.testing.assert_array_equal(back["render"], view["color"])
