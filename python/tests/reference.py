"""The pure-Python decode of an nrw-etl dataset (pyarrow + Pillow + OpenEXR, as
docs/python_reader.py reads it): the oracle of the package's arrays and the benchmark's peer.
It knows the format from schemas/views.toml only, not from the package."""

import io
import json
import os

import numpy as np
import OpenEXR
import pyarrow.parquet as pq
from PIL import Image

# Payload column -> key of nrw.Dataset's view dicts.
IMAGES = {
    "photo_png": "photo",
    "color_png": "color",
    "normal_png": "normals",
    "semantics_png": "semantics",
    "labels_png": "labels",
    "transient_png": "transient",
}
PAYLOADS = [*IMAGES, "depth_exr"]


def shard_paths(root):
    """The view shards the manifest lists, in its order."""
    with open(os.path.join(root, "manifest.json")) as f:
        tables = json.load(f)["tables"]
    return [os.path.join(root, t["path"]) for t in tables if t["path"].startswith("shards/")]


def rows(root):
    """Every shard row as a dict (payloads still encoded), in file order."""
    for path in shard_paths(root):
        yield from pq.read_table(path).to_pylist()


def decode(row):
    """A row's payloads decoded: the arrays nrw.Dataset must give."""
    out = {"image_id": row["image_id"], "name": row["name"]}
    for column, key in IMAGES.items():
        if row.get(column) is not None:
            out[key] = np.asarray(Image.open(io.BytesIO(row[column])))
    exr = OpenEXR.File(io.BytesIO(row["depth_exr"]))
    out["depth"] = np.asarray(exr.channels()["Z"].pixels, np.float32)
    return out


def splits(root):
    """image id -> split name, from splits.parquet (empty before `nrw-etl split`)."""
    path = os.path.join(root, "splits.parquet")
    if not os.path.exists(path):
        return {}
    return {r["image_id"]: r["split"] for r in pq.read_table(path).to_pylist()}
