"""nrw.torch under a real DataLoader and a real process group (needs PyTorch: tests/python_pkg.rs
runs this file with NRW_TORCH_PYTHON, as CI does, where no test may skip; the same split over
readers is checked without torch in test_loader.py)."""

import os

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")

import nrw  # noqa: E402
import nrw.torch as nt  # noqa: E402
from nrw.loader import Crops  # noqa: E402
from torch.utils.data import DataLoader  # noqa: E402


def epoch_ids(dataset, rank, world_size, epoch, workers=2):
    ds = nt.CropDataset(dataset, "train", crop=32, seed=1, rank=rank, world_size=world_size)
    ds.set_epoch(epoch)
    loader = DataLoader(ds, batch_size=3, num_workers=workers)
    ids, positions = [], []
    for batch in loader:
        assert batch["photo"].shape[1:] == (3, 32, 32) and batch["photo"].dtype == torch.float32
        assert batch["depth"].shape[1:] == (1, 32, 32)
        ids += batch["image_id"].tolist()
        positions += batch["position"].tolist()
    return ids, positions


def test_two_dataloader_workers_times_two_ranks_see_every_view_once(demo):
    want = sorted(nrw.Dataset(demo).ids("train"))
    for epoch in (0, 1):
        ids, positions = [], []
        for rank in (0, 1):
            i, p = epoch_ids(demo, rank, 2, epoch)
            ids, positions = ids + i, positions + p
        assert sorted(ids) == want, epoch
        assert sorted(positions) == list(range(len(want)))


def _rank_main(rank, demo, out):
    import torch.distributed as dist

    dist.init_process_group("gloo", rank=rank, world_size=2, init_method=f"file://{out}/rendezvous")
    ids, _ = epoch_ids(demo, None, None, 0)  # rank and world size from the process group
    with open(os.path.join(out, f"rank{rank}"), "w") as f:
        f.write(" ".join(map(str, ids)))
    dist.destroy_process_group()


def test_ranks_come_from_the_process_group(demo, tmp_path):
    torch.multiprocessing.spawn(_rank_main, args=(demo, str(tmp_path)), nprocs=2)
    ids = [int(i) for r in (0, 1) for i in (tmp_path / f"rank{r}").read_text().split()]
    assert sorted(ids) == sorted(nrw.Dataset(demo).ids("train"))
    assert (tmp_path / "rank0").read_text() != (tmp_path / "rank1").read_text()


def test_crop_dataset_items_are_the_loader_crops(demo):
    ds = nrw.Dataset(demo)
    want = {i["position"]: i for i in Crops(ds, "train", crop=40, seed=4).epoch(3)}
    torch_ds = nt.CropDataset(ds, "train", crop=40, seed=4)
    torch_ds.set_epoch(3)
    got = list(DataLoader(torch_ds, batch_size=None, num_workers=2))
    assert sorted(i["position"] for i in got) == sorted(want)
    for item in got:
        np.testing.assert_array_equal(item["color"].numpy(), want[item["position"]]["color"])


def test_triplet_dataset_draws_do_not_depend_on_workers(demo):
    def draws(workers):
        ds = nt.TripletDataset(demo, steps=12, crop=32, seed=2, pos_k=3, neg_k=5)
        out = {}
        for b in DataLoader(ds, batch_size=None, num_workers=workers):
            ids = (b["anchor_id"], b["positive_id"], b["negative_id"])
            out[b["index"]] = (ids, b["anchor"].sum().item(), b["negative"].sum().item())
        return out

    one, two = draws(0), draws(2)
    assert one == two and sorted(one) == list(range(12))
    assert len({ids for ids, _, _ in one.values()}) > 1
