"""Crops equal the Rust Loader's for the same seed; triplets are the Rust sampler's draws;
readers of an epoch cover every view exactly once."""

import json
import os
from collections import Counter

import numpy as np
import pytest

import nrw
from nrw.loader import Crops, reader_of


def rust(draws):
    with open(os.path.join(draws, "index.json")) as f:
        return json.load(f)


def test_crops_equal_the_rust_loaders_for_the_same_seed(demo, rust_draws):
    want = rust(rust_draws)
    crops = Crops(nrw.Dataset(demo), want["split"], crop=want["crop"], seed=want["seed"])
    s = want["crop"]
    got = {}
    for epoch in (0, 1):
        assert crops.order(epoch) == [c["image_id"] for c in want["crops"] if c["epoch"] == epoch]
        for item in crops.epoch(epoch):
            got[(epoch, item["position"])] = item
    assert len(got) == len(want["crops"]) > 0
    for c in want["crops"]:
        item = got[(c["epoch"], c["position"])]
        assert (item["image_id"], item["x"], item["y"]) == (c["image_id"], c["x"], c["y"]), c
        values = np.fromfile(os.path.join(rust_draws, c["file"]), dtype="<f4")
        photo, color, depth = np.split(values, [3 * s * s, 6 * s * s])
        np.testing.assert_array_equal(item["photo"], photo.reshape(3, s, s))
        np.testing.assert_array_equal(item["color"], color.reshape(3, s, s))
        np.testing.assert_array_equal(item["depth"], depth.reshape(1, s, s))
    # Two epochs differ in order and places.
    assert [got[(0, p)]["image_id"] for p in range(4)] != [got[(1, p)]["image_id"] for p in range(4)]


def test_triplets_are_the_rust_samplers_draws(demo, rust_draws):
    want = rust(rust_draws)["triplets"]
    settings = {k: want[k] for k in ("pos_k", "neg_k", "hold_out_every", "seed")}
    sampler = nrw.TripletSampler(nrw.Dataset(demo), **settings)
    assert [list(t) for t in sampler.sample(40)] == want["sample"]
    assert [list(t) for t in sampler.held_out()] == want["held_out"]
    sampler.reseed(want["seed"])
    assert [list(t) for t in sampler.sample(40)] == want["sample"]


def test_triplet_draws_follow_the_paper(demo):
    ds = nrw.Dataset(demo)
    table = {r["anchor_id"]: r for r in ds.triplets().to_pylist()}
    sampler = nrw.TripletSampler(ds, pos_k=3, neg_k=5, hold_out_every=5, seed=3)
    held = {a for a, _, _ in sampler.held_out()}
    for a, p, n in sampler.sample(500):
        assert p in table[a]["nearest_ids"][:3] and n in table[a]["furthest_ids"][:5]
        assert not held & {a, p, n}
    with pytest.raises(ValueError, match="pos_k: 99"):
        nrw.TripletSampler(ds, pos_k=99)


def test_two_workers_times_two_ranks_see_every_view_once_per_epoch(demo):
    ds = nrw.Dataset(demo)
    for split in ("train", "val"):
        crops = Crops(ds, split, crop=32, seed=5)
        for epoch in range(3):
            seen = Counter()
            for rank in range(2):
                for worker in range(2):
                    reader, readers = reader_of(rank, 2, worker, 2)
                    for item in crops.epoch(epoch, reader, readers):
                        seen[item["image_id"]] += 1
                        assert item["epoch"] == epoch and item["position"] % readers == reader
            assert seen == Counter(ds.ids(split)), (split, epoch)


def test_splitting_over_readers_does_not_change_a_crop(demo):
    ds = nrw.Dataset(demo)
    crops = Crops(ds, "train", crop=48, seed=9)
    whole = {i["position"]: i for i in crops.epoch(2)}
    for reader in range(3):
        for item in crops.epoch(2, reader, 3):
            ref = whole[item["position"]]
            assert (item["image_id"], item["x"], item["y"]) == (ref["image_id"], ref["x"], ref["y"])
            np.testing.assert_array_equal(item["photo"], ref["photo"])


def test_bad_settings_name_the_setting(demo):
    ds = nrw.Dataset(demo)
    with pytest.raises(ValueError, match="crop: must be positive"):
        Crops(ds, crop=0)
    with pytest.raises(ValueError, match="does not fit in"):
        next(Crops(ds, crop=5000).epoch(0))
    with pytest.raises(ValueError, match="rank 2 is not in 0..2"):
        reader_of(2, 2, 0, 2)


def test_the_old_shard_name_warns_and_gives_the_reader():
    import nrw.loader

    with pytest.warns(DeprecationWarning, match="shard_of is now reader_of"):
        assert nrw.loader.shard_of(1, 2, 1, 3) == reader_of(1, 2, 1, 3) == (4, 6)
