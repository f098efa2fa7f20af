"""PyTorch datasets over nrw-etl datasets (needs `torch`; `import nrw` alone does not).

`CropDataset` is an `IterableDataset` of aligned random crops of one split, the crops the
Rust trainer's `Loader` takes for the same seed; `TripletDataset` yields the appearance
encoder's (anchor, positive, negative) crops drawn as the paper's code draws them. Both are
split over DataLoader workers and distributed ranks without duplicates:

>>> ds = nrw.torch.CropDataset("/tmp/nrw-demo/dataset", "train", crop=256, seed=0)
>>> loader = torch.utils.data.DataLoader(ds, batch_size=8, num_workers=2)
>>> for epoch in range(10):
...     ds.set_epoch(epoch)                 # before each epoch, as with DistributedSampler
...     for batch in loader: ...            # batch["photo"]: B x 3 x S x S float32 in [-1, 1]

A dataset given as a path or URL is opened in each worker process (an `nrw.Dataset` given
directly is reopened there from its location and options).
"""

from __future__ import annotations

import os
import warnings
from typing import Iterator, Mapping, Optional, Union

import numpy as np
import torch
import torch.distributed as dist
from torch.utils.data import IterableDataset, get_worker_info

from ._nrw import Dataset, TripletSampler, crop_place
from ._view import View
from .loader import Crops, normalise, reader_of

__all__ = ["CropDataset", "TripletDataset", "current_reader", "process_rank"]

Source = Union[str, "os.PathLike[str]", Dataset]


def _open(source: Source, options: Optional[Mapping[str, str]]) -> Dataset:
    return source if isinstance(source, Dataset) else Dataset(source, options)


def process_rank(rank: Optional[int] = None, world_size: Optional[int] = None) -> tuple[int, int]:
    """(rank, world_size): the ones given, else torch.distributed's when it is initialised,
    else one process. Read where the dataset is made, in the rank's main process, as
    DistributedSampler does (a DataLoader worker does not see the process group)."""
    if rank is not None and world_size is not None:
        return rank, world_size
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def current_reader(rank: int, world_size: int) -> tuple[int, int]:
    """(reader, readers) of the calling DataLoader worker of `rank`: workers from
    `get_worker_info()`, one when iterated in the main process."""
    info = get_worker_info()
    worker, workers = (info.id, info.num_workers) if info is not None else (0, 1)
    return reader_of(rank, world_size, worker, workers)


def current_shard(rank: int, world_size: int) -> tuple[int, int]:
    """Deprecated name of `current_reader` ("shard" now means only a Parquet file of views)."""
    warnings.warn("nrw.torch.current_shard is now current_reader", DeprecationWarning, stacklevel=2)
    return current_reader(rank, world_size)


def _tensors(item: dict) -> View:
    return View(
        {k: torch.from_numpy(v) if isinstance(v, np.ndarray) else v for k, v in item.items()}
    )


class CropDataset(IterableDataset):
    """Aligned random crops of one split: each item is a dict of `photo` (3 x S x S), `color`
    (3 x S x S, -1 where nothing was drawn), `depth` (1 x S x S, in [0, 1]) float32 tensors,
    `semantics` when asked for and present, and `image_id`, `x`, `y`, `epoch`, `position`."""

    def __init__(
        self,
        dataset: Source,
        split: str = "train",
        crop: int = 256,
        seed: int = 0,
        semantics: bool = False,
        rank: Optional[int] = None,
        world_size: Optional[int] = None,
        options: Optional[Mapping[str, str]] = None,
    ) -> None:
        super().__init__()
        self.crops = Crops(_open(dataset, options), split, crop, seed, semantics)
        self.rank, self.world_size = process_rank(rank, world_size)
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """The epoch the next iteration draws (its order and crop places)."""
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.crops)

    def __iter__(self) -> Iterator[dict]:
        reader, readers = current_reader(self.rank, self.world_size)
        for item in self.crops.epoch(self.epoch, reader, readers):
            yield _tensors(item)


class TripletDataset(IterableDataset):
    """`steps` triplets per epoch, each a dict of `anchor`, `positive`, `negative` photo crops
    (3 x S x S float32 in [-1, 1]), their image ids and the triplet's `index` in the epoch:
    the appearance encoder's training data.
    Triplet k of an epoch goes to reader k mod readers; its ids come from a `TripletSampler`
    seeded by (seed, epoch, k), and crop j of it from position 3k + j, so the draws do not
    depend on the number of workers or ranks."""

    def __init__(
        self,
        dataset: Source,
        steps: int,
        crop: int = 256,
        seed: int = 0,
        pos_k: int = 5,
        neg_k: int = 13,
        hold_out_every: int = 5,
        rank: Optional[int] = None,
        world_size: Optional[int] = None,
        options: Optional[Mapping[str, str]] = None,
    ) -> None:
        super().__init__()
        if steps <= 0:
            raise ValueError(f"steps: must be positive, got {steps}")
        self.dataset = _open(dataset, options)
        self.steps, self.crop, self.seed = steps, crop, seed
        self.draw = dict(pos_k=pos_k, neg_k=neg_k, hold_out_every=hold_out_every)
        # Made here so settings the triplet table cannot meet are refused now, not in a
        # worker; remade in a worker (it does not pickle).
        self._sampler: Optional[TripletSampler] = TripletSampler(self.dataset, seed=seed, **self.draw)
        self.rank, self.world_size = process_rank(rank, world_size)
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """The epoch the next iteration draws."""
        self.epoch = epoch

    def __len__(self) -> int:
        return self.steps

    def triplet(self, k: int) -> tuple[int, int, int]:
        """Triplet k of the current epoch (image ids)."""
        if self._sampler is None:
            self._sampler = TripletSampler(self.dataset, seed=self.seed, **self.draw)
        self._sampler.reseed((self.seed * 1_000_003 + self.epoch * 7_919 + k) % (1 << 64))
        return self._sampler.sample(1)[0]

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_sampler": None}

    def __iter__(self) -> Iterator[dict]:
        reader, readers = current_reader(self.rank, self.world_size)
        for k in range(reader, self.steps, readers):
            ids = self.triplet(k)
            views = self.dataset.get_many(list(ids))
            item: dict = {"index": k}
            for j, (role, view) in enumerate(zip(("anchor", "positive", "negative"), views)):
                h, w = view["photo"].shape[:2]
                if self.crop > min(w, h):
                    raise ValueError(
                        f"{self.dataset.location}: image {view['image_id']}: a {self.crop}x"
                        f"{self.crop} crop does not fit in {w}x{h}"
                    )
                x, y = crop_place(self.seed, self.epoch, 3 * k + j, w - self.crop, h - self.crop)
                item[role] = torch.from_numpy(normalise(view, x, y, self.crop, 1.0, False)["photo"])
                item[f"{role}_id"] = view["image_id"]
            yield item
