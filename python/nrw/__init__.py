"""Read nrw-etl aligned datasets (Neural Rerendering in the Wild) into NumPy and pyarrow.

>>> import nrw
>>> ds = nrw.Dataset("/tmp/nrw-demo/dataset")          # or s3://bucket/prefix, gs://, az://
>>> len(ds), ds.splits()
>>> for view in ds.views("train"):                     # dicts of NumPy arrays
...     view["photo"].shape, view["color"].shape, view["depth"].dtype

Payloads are decoded in Rust with the GIL released, each checked against its CRC-32 first;
`nrw.loader.Crops` takes the aligned random crops the Rust trainer takes, and `nrw.torch`
(imported on its own, it needs PyTorch) wraps them as `IterableDataset`s.
"""

from ._nrw import (
    SCHEMA_VERSION,
    Dataset,
    DatasetError,
    TripletSampler,
    ViewIter,
    crop_place,
    epoch_order,
)

__all__ = [
    "SCHEMA_VERSION",
    "Dataset",
    "DatasetError",
    "TripletSampler",
    "ViewIter",
    "crop_place",
    "epoch_order",
]
