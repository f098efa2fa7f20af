"""Type stubs of nrw._nrw, the compiled half of the nrw package."""

import os
from typing import Iterator, Mapping, Optional, Sequence, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt
import pyarrow as pa

SCHEMA_VERSION: int
"""The dataset schema version this package reads; others are refused by name."""

class DatasetError(Exception):
    """A dataset that cannot be read: the message names the file, and the record and field
    where it applies (a payload whose CRC-32 does not match names shard file, row and column)."""

class View(TypedDict, total=False):
    """One kept view, every payload decoded (the optional keys appear when the dataset has them)."""

    image_id: int
    name: str
    photo: npt.NDArray[np.uint8]
    """The resized photo, H x W x 3 RGB."""
    color: npt.NDArray[np.uint8]
    """The colour render, H x W x 4 RGBA; alpha is coverage (255 where a point was drawn).
    `view["render"]`, its earlier name, still reads it with a DeprecationWarning."""
    depth: npt.NDArray[np.float32]
    """Camera-space depth, H x W, 0 where empty."""
    normals: npt.NDArray[np.uint8]
    """Camera-space normals mapped from [-1, 1] to 0..255, H x W x 3 (0 where empty)."""
    semantics: npt.NDArray[np.uint8]
    """ADE20K colour-coded labels, H x W x 3."""
    labels: npt.NDArray[np.uint8]
    """ADE20K class ids, H x W (0 = unlabelled)."""
    transient: npt.NDArray[np.uint8]
    """Transient-object mask, H x W (255 = transient)."""
    camera_id: int
    model: str
    """COLMAP camera model of `params` (intrinsics in the resized photo's pixels)."""
    params: list[float]
    qvec: list[float]
    """World-to-camera rotation (w, x, y, z)."""
    tvec: list[float]
    """World-to-camera translation."""

class ViewIter(Iterator[View]):
    """Views streamed a row group at a time (memory stays at one row group's views)."""

    def __len__(self) -> int:
        """Views still to come."""
    def __next__(self) -> View: ...

class Dataset:
    """An nrw-etl dataset: a local folder or an `s3://`, `gs://` or `az://` URL.

    Object-store credentials come from the environment as for the CLI (`AWS_*`,
    `GOOGLE_*`, `AZURE_*`), or from `options` (the variables' names in lower case, e.g.
    `{"aws_endpoint_url": "http://127.0.0.1:5000"}`). Opening reads the manifest (a dataset
    of another schema version is refused, naming both versions) and the shard index.
    """

    def __init__(
        self,
        location: Union[str, "os.PathLike[str]"],
        options: Optional[Mapping[str, str]] = None,
    ) -> None: ...
    def __len__(self) -> int:
        """Number of kept views."""
    def __contains__(self, image_id: int) -> bool: ...
    @property
    def location(self) -> str: ...
    @property
    def schema_version(self) -> int: ...
    @property
    def depth_max(self) -> Optional[float]:
        """The scene's largest depth (what the Rust loader divides depth by), if recorded."""
    def splits(self) -> dict[str, int]:
        """Split names with their sizes (`{"all": n}` before `nrw-etl split`)."""
    def ids(self, split: Optional[str] = None) -> list[int]:
        """A split's image ids, sorted; every kept view's, in file order, when `split` is None."""
    def views(self, split: Optional[str] = None, *, ids: Optional[Sequence[int]] = None) -> ViewIter:
        """Stream the views of a split (or of `ids`, or of every kept view) in file order; an
        id given twice is yielded once."""
    def get(self, image_id: int) -> View:
        """One view by image id (KeyError when it is not a kept view)."""
    def get_many(self, ids: Sequence[int]) -> list[View]:
        """Views in the order of `ids`, each row group read once, decoded in parallel."""
    def triplets(self) -> Optional[pa.Table]:
        """triplets.parquet (nearest and furthest photos in style per anchor), None before
        `nrw-etl triplets`; its manifest hash is checked and its buffers shared, not copied."""
    def descriptors(self) -> Optional[pa.Table]:
        """Every style descriptor the manifest lists, each row's CRC-32 checked; None before
        `nrw-etl style`."""

class TripletSampler:
    """(anchor, positive, negative) image ids drawn as the paper's code draws them: the positive
    uniformly among an anchor's `pos_k` nearest photos in style, the negative among its `neg_k`
    furthest; every `hold_out_every`-th photo (by a hash of its id) is kept out of training.
    The same seed draws what the Rust trainer (`nrw-train`) draws."""

    def __init__(
        self,
        dataset: Dataset,
        pos_k: int = 5,
        neg_k: int = 13,
        hold_out_every: int = 5,
        seed: int = 0,
    ) -> None: ...
    def reseed(self, seed: int) -> None:
        """Restart the draws from `seed`, as if the sampler had just been made with it."""
    def sample(self, n: int) -> list[Tuple[int, int, int]]:
        """`n` training triplets, drawn with replacement."""
    def held_out(self) -> list[Tuple[int, int, int]]:
        """Every combination of the held-out anchors (for evaluation)."""
    @property
    def train_anchors(self) -> int: ...

def epoch_order(ids: Sequence[int], seed: int, epoch: int) -> list[int]:
    """The order of an epoch: the permutation the Rust loader draws from (seed, epoch)."""

def crop_place(seed: int, epoch: int, position: int, max_x: int, max_y: int) -> Tuple[int, int]:
    """The crop's top-left corner for the view at `position` of `epoch`, as the Rust loader
    draws it (uniform in 0..=max_x, 0..=max_y)."""
