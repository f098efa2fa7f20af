"""Independent oracle of triplets.parquet: numpy's float64 all-pairs distances over the
training photos (read from the dataset's Parquet files with pyarrow, none of our code), each
anchor's k nearest and k furthest by (distance, id), compared with the stored ids and their
stored squared distances. Usage: python3 triplets_oracle.py DATASET K"""

import glob
import os
import sys

import numpy as np
import pyarrow.parquet as pq

ds, k = sys.argv[1], int(sys.argv[2])
desc = pq.read_table(glob.glob(os.path.join(ds, "descriptors", "part-*.parquet"))).to_pydict()
vectors = {i: np.asarray(v, dtype=np.float64) for i, v in zip(desc["image_id"], desc["descriptor"])}
splits = pq.read_table(os.path.join(ds, "splits.parquet")).to_pydict()
train = sorted(i for i, s in zip(splits["image_id"], splits["split"]) if s == "train")
x = np.stack([vectors[i] for i in train])
ids = np.asarray(train)
# Squared distances by differences, not the GEMM identity: every pair exact to float64.
d2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2)
got = pq.read_table(os.path.join(ds, "triplets.parquet")).to_pydict()
assert sorted(got["anchor_id"]) == train, (got["anchor_id"], train)
for row, anchor in enumerate(got["anchor_id"]):
    a = train.index(anchor)
    others = np.asarray([j for j in range(len(train)) if j != a])
    dist = d2[a, others]
    near = others[np.lexsort((ids[others], dist))][:k]
    far = others[np.lexsort((ids[others], -dist))][:k]
    for kind, want in (("nearest", near), ("furthest", far)):
        assert got[f"{kind}_ids"][row] == ids[want].tolist(), (anchor, kind, got[f"{kind}_ids"][row], ids[want])
        stored = np.asarray(got[f"{kind}_d2"][row])
        assert np.allclose(stored, d2[a, want], rtol=1e-12, atol=0), (anchor, kind, stored, d2[a, want])
print(f"{len(train)} anchors: nearest and furthest equal numpy's")
