"""Aligned random crops of one split, epoch after epoch, exactly as the Rust trainer's
`Loader` takes them, split over reading processes without duplicates. NumPy only: `nrw.torch`
wraps this for PyTorch's DataLoader.

>>> crops = Crops(nrw.Dataset("/tmp/nrw-demo/dataset"), "train", crop=256, seed=7)
>>> for item in crops.epoch(0):                 # every view of the split once, as float32 CHW
...     item["photo"].shape, item["color"].shape, item["depth"].shape   # (3,S,S) (3,S,S) (1,S,S)

The order of an epoch and each crop's place come from (seed, epoch, position in the epoch),
drawn by the same Rust code as the trainer's, so crops do not depend on how many workers or
ranks share the epoch: reader `r` of `n` takes positions r, r+n, r+2n, ... (a reader is one
process's slice of the epoch: one DataLoader worker of one rank; "shard" means a Parquet file)
"""

from __future__ import annotations

import warnings
from typing import Iterator, Sequence

import numpy as np

from ._nrw import Dataset, crop_place, epoch_order
from ._view import View

_HALF = np.float32(127.5)
_ONE = np.float32(1.0)


def to_unit(pixels: np.ndarray) -> np.ndarray:
    """uint8 H x W x C to float32 C x H x W in [-1, 1], computed as the Rust loader does
    (`px as f32 / 127.5 - 1.0`, in float32)."""
    return np.ascontiguousarray((pixels.astype(np.float32) / _HALF - _ONE).transpose(2, 0, 1))


def normalise(view: dict, x: int, y: int, size: int, depth_scale: float, semantics: bool) -> dict:
    """The crop at (x, y) of every channel of a decoded view, normalised as the Rust `Loader`
    normalises a batch item: photo and colour render in [-1, 1] (-1 where nothing was drawn),
    depth / depth_scale clipped to [0, 1] (0 where empty or not finite)."""
    s = np.s_[y : y + size, x : x + size]
    color = view["color"][s]
    out = View({
        "image_id": view["image_id"],
        "x": x,
        "y": y,
        "photo": to_unit(view["photo"][s]),
        "color": to_unit(color[..., :3]),
    })
    out["color"][:, color[..., 3] == 0] = -_ONE
    d = view["depth"][s]
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(d) & (d > 0)
        scaled = np.minimum(d / np.float32(depth_scale), _ONE)
    out["depth"] = np.where(keep, scaled, np.float32(0))[None].astype(np.float32)
    if semantics and "semantics" in view:
        out["semantics"] = to_unit(view["semantics"][s])
    return out


class Crops:
    """The aligned random crops of one split (see the module's documentation)."""

    def __init__(
        self,
        dataset: Dataset,
        split: str = "train",
        crop: int = 256,
        seed: int = 0,
        semantics: bool = False,
        read_ahead: int = 8,
    ) -> None:
        if crop <= 0:
            raise ValueError(f"crop: must be positive, got {crop}")
        if read_ahead <= 0:
            raise ValueError(f"read_ahead: must be positive, got {read_ahead}")
        self.dataset = dataset
        self.split = split
        self.crop = crop
        self.seed = seed
        self.semantics = semantics
        self.read_ahead = read_ahead
        self.ids = dataset.ids(split)
        if not self.ids:
            raise ValueError(f"{dataset.location}: split {split!r} holds no views")
        depth_max = dataset.depth_max
        # The Rust loader's scale: the scene's largest depth, 1 when unknown; as float32.
        self.depth_scale = float(np.float32(depth_max if depth_max and depth_max > 0 else 1.0))

    def __len__(self) -> int:
        return len(self.ids)

    def order(self, epoch: int) -> list[int]:
        """The image ids of an epoch in its order (the Rust `Loader::epoch_order`)."""
        return epoch_order(self.ids, self.seed, epoch)

    def positions(self, epoch: int, reader: int = 0, readers: int = 1) -> list[tuple[int, int]]:
        """(position, image id) pairs reader `reader` of `readers` takes in `epoch`."""
        if not 0 <= reader < readers:
            raise ValueError(f"reader {reader} is not in 0..{readers}")
        order = self.order(epoch)
        return [(p, order[p]) for p in range(reader, len(order), readers)]

    def item(self, view: dict, epoch: int, position: int) -> dict:
        """The crop of a decoded view at `position` of `epoch`."""
        h, w = view["photo"].shape[:2]
        if self.crop > w or self.crop > h:
            raise ValueError(
                f"{self.dataset.location}: image {view['image_id']}: a {self.crop}x{self.crop} "
                f"crop does not fit in {w}x{h}"
            )
        x, y = crop_place(self.seed, epoch, position, w - self.crop, h - self.crop)
        out = normalise(view, x, y, self.crop, self.depth_scale, self.semantics)
        out["epoch"], out["position"] = epoch, position
        return out

    def epoch(self, epoch: int, reader: int = 0, readers: int = 1) -> Iterator[dict]:
        """This reader's crops of `epoch`, in epoch order (views read `read_ahead` at a time)."""
        todo = self.positions(epoch, reader, readers)
        for at in range(0, len(todo), self.read_ahead):
            chunk: Sequence[tuple[int, int]] = todo[at : at + self.read_ahead]
            views = self.dataset.get_many([i for _, i in chunk])
            for (position, _), view in zip(chunk, views):
                yield self.item(view, epoch, position)


def reader_of(rank: int, world_size: int, worker: int, workers: int) -> tuple[int, int]:
    """The reader (index, count) of one DataLoader worker of one distributed rank: ranks split
    an epoch first, then each rank's workers, so every position goes to exactly one."""
    for name, value, bound in (("rank", rank, world_size), ("worker", worker, workers)):
        if not 0 <= value < bound:
            raise ValueError(f"{name} {value} is not in 0..{bound}")
    return rank * workers + worker, world_size * workers


def shard_of(rank: int, world_size: int, worker: int, workers: int) -> tuple[int, int]:
    """Deprecated name of `reader_of` ("shard" now means only a Parquet file of views)."""
    warnings.warn("nrw.loader.shard_of is now reader_of", DeprecationWarning, stacklevel=2)
    return reader_of(rank, world_size, worker, workers)

