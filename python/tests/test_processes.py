"""What a DataLoader relies on, tested without PyTorch: an `nrw.Dataset` pickles as its location
and reopens in another process; a forked child (a DataLoader worker under the default start
method) reads with its own object-store runtime and decoding pool instead of hanging on the
parent's; and nrw.torch's split over workers x ranks covers every item once, run against a
minimal stand-in for the three torch names it calls (the real thing: test_torch.py)."""

import hashlib
import importlib
import multiprocessing
import os
import pickle
import signal
import sys
import time
import types
from collections import Counter

import numpy as np
import pytest

import nrw
from nrw.loader import reader_of


def digest(ds, ids):
    """SHA-256 over every array of the views `ids`, in order."""
    h = hashlib.sha256()
    for view in ds.get_many(list(ids)):
        for key in sorted(view):
            if isinstance(view[key], np.ndarray):
                h.update(key.encode())
                h.update(np.ascontiguousarray(view[key]).tobytes())
    return h.hexdigest()


def test_a_dataset_pickles_as_its_location_and_reads_the_same(demo):
    ds = nrw.Dataset(demo)
    again = pickle.loads(pickle.dumps(ds))
    assert type(again) is nrw.Dataset and again is not ds
    assert again.location == ds.location and len(again) == len(ds)
    assert again.ids("train") == ds.ids("train")
    ids = sorted(ds.ids("train"))[:3]
    assert digest(again, ids) == digest(ds, ids)
    # The pickle holds the location, not views: small whatever the dataset.
    assert len(pickle.dumps(ds)) < 1024


def _wait(pid, seconds):
    """The child's exit status, or kill it and fail after `seconds` (a hang is the bug)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        time.sleep(0.05)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    pytest.fail(f"forked child {pid} did not finish in {seconds} s")


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")
def test_a_forked_child_reads_with_its_own_pool(demo):
    ds = nrw.Dataset(demo)
    ids = sorted(ds.ids())
    # The parent has opened the dataset and run its decoding pool before the fork, as a
    # training script does before its DataLoader starts workers.
    want = digest(ds, ids)
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: report and leave without running the parent's handlers
        os.close(r)
        try:
            os.write(w, digest(ds, ids).encode())
            code = 0
        except BaseException as e:  # noqa: BLE001 - reported to the parent
            os.write(w, f"error: {e!r}".encode())
            code = 1
        os.close(w)
        os._exit(code)
    os.close(w)
    code = _wait(pid, 120)
    got = os.read(r, 4096).decode()
    os.close(r)
    assert code == 0 and got == want, got
    # The parent still reads after its child is gone.
    assert digest(ds, ids[:2]) == digest(nrw.Dataset(demo), ids[:2])


def _worker_digest(args):
    ds, ids = args
    return os.getpid(), digest(ds, ids)


@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_multiprocessing_workers_read_what_the_parent_reads(demo, method):
    if method not in multiprocessing.get_all_start_methods():
        pytest.skip(f"start method {method} is not available here")
    ds = nrw.Dataset(demo)
    ids = sorted(ds.ids())
    groups = [ids[i::3] for i in range(3)]
    want = [digest(ds, g) for g in groups]
    ctx = multiprocessing.get_context(method)
    with ctx.Pool(2) as pool:
        got = pool.map_async(_worker_digest, [(ds, g) for g in groups]).get(timeout=180)
    assert [d for _, d in got] == want
    assert all(pid != os.getpid() for pid, _ in got)


class _WorkerInfo:
    def __init__(self, id, num_workers):
        self.id, self.num_workers = id, num_workers


def _torch_stand_in(state):
    """The names nrw.torch takes from torch, no more: `from_numpy`, the process group's
    rank and size, `IterableDataset` and `get_worker_info` (answered from `state`)."""
    torch = types.ModuleType("torch")
    torch.from_numpy = lambda a: a
    dist = types.ModuleType("torch.distributed")
    dist.is_available = lambda: True
    dist.is_initialized = lambda: state.get("group") is not None
    dist.get_rank = lambda: state["group"][0]
    dist.get_world_size = lambda: state["group"][1]
    utils = types.ModuleType("torch.utils")
    data = types.ModuleType("torch.utils.data")
    data.IterableDataset = object
    data.get_worker_info = lambda: state.get("worker")
    torch.distributed, torch.utils, utils.data = dist, utils, data
    return {"torch": torch, "torch.distributed": dist, "torch.utils": utils, "torch.utils.data": data}


@pytest.fixture
def nrw_torch(monkeypatch):
    """nrw.torch imported against the stand-in, and the state its calls answer from; the real
    modules (if any) come back afterwards."""
    state = {}
    for name, module in _torch_stand_in(state).items():
        monkeypatch.setitem(sys.modules, name, module)
    monkeypatch.delitem(sys.modules, "nrw.torch", raising=False)
    monkeypatch.delattr(nrw, "torch", raising=False)
    module = importlib.import_module("nrw.torch")
    yield module, state
    sys.modules.pop("nrw.torch", None)
    if hasattr(nrw, "torch"):
        delattr(nrw, "torch")


def test_torch_layer_splits_crops_over_workers_and_ranks_once(demo, nrw_torch):
    nt, state = nrw_torch
    want = Counter(nrw.Dataset(demo).ids("train"))
    for epoch in (0, 1):
        seen, positions = Counter(), []
        for rank in range(2):
            ds = nt.CropDataset(demo, "train", crop=32, seed=1, rank=rank, world_size=2)
            ds.set_epoch(epoch)
            for worker in range(2):
                state["worker"] = _WorkerInfo(worker, 2)
                for item in ds:
                    seen[item["image_id"]] += 1
                    positions.append(item["position"])
                    assert item["photo"].shape == (3, 32, 32) and item["epoch"] == epoch
        assert seen == want, epoch
        assert sorted(positions) == list(range(sum(want.values())))


def test_torch_layer_takes_ranks_from_the_process_group(demo, nrw_torch):
    nt, state = nrw_torch
    assert nt.process_rank() == (0, 1)
    state["group"] = (1, 4)
    assert nt.process_rank() == (1, 4)
    assert nt.process_rank(0, 2) == (0, 2)
    ds = nt.CropDataset(demo, "train", crop=32, seed=1)
    assert (ds.rank, ds.world_size) == (1, 4)
    state["worker"] = _WorkerInfo(2, 3)
    assert nt.current_reader(1, 4) == reader_of(1, 4, 2, 3)


def test_torch_layer_triplets_go_once_each_and_survive_a_pickle(demo, nrw_torch):
    nt, state = nrw_torch
    steps = 11
    whole = nt.TripletDataset(demo, steps, crop=32, seed=3, pos_k=2, neg_k=3)
    whole.set_epoch(1)
    want = {k: whole.triplet(k) for k in range(steps)}
    got = {}
    for rank in range(2):
        ds = nt.TripletDataset(demo, steps, crop=32, seed=3, pos_k=2, neg_k=3, rank=rank, world_size=2)
        ds.set_epoch(1)
        # A DataLoader hands each worker a pickled copy: the sampler is dropped and remade.
        copy = pickle.loads(pickle.dumps(ds))
        assert copy._sampler is None
        for worker in range(2):
            state["worker"] = _WorkerInfo(worker, 2)
            for item in copy:
                k = item["index"]
                assert k not in got, k
                got[k] = (item["anchor_id"], item["positive_id"], item["negative_id"])
                assert item["anchor"].shape == (3, 32, 32)
    assert got == want
