"""Training tensors from nrw-etl shards with pyarrow alone: python3 docs/python_reader.py DATASET [CROP]"""
import io, json, sys
import numpy as np, OpenEXR, pyarrow.parquet as pq
from PIL import Image


def views(root, split="train", crop=256, rng=np.random.default_rng(0)):
    ids = {r["image_id"] for r in pq.read_table(f"{root}/splits.parquet").to_pylist() if r["split"] == split}
    for t in (t for t in json.load(open(f"{root}/manifest.json"))["tables"] if t["path"].startswith("shards/")):
        for row in (r for r in pq.read_table(f"{root}/{t['path']}").to_pylist() if r["image_id"] in ids):
            photo = np.asarray(Image.open(io.BytesIO(row["photo_png"])), np.float32) / 255
            render = np.asarray(Image.open(io.BytesIO(row["color_png"])), np.float32) / 255  # alpha = coverage
            depth = np.asarray(OpenEXR.File(io.BytesIO(row["depth_exr"])).channels()["Z"].pixels, np.float32)
            y, x = rng.integers(0, photo.shape[0] - crop + 1), rng.integers(0, photo.shape[1] - crop + 1)
            s = np.s_[y:y + crop, x:x + crop]
            yield row["image_id"], photo[s], render[s], depth[s][..., None]  # HWC, one place in every channel


for image_id, photo, render, depth in views(sys.argv[1], crop=int(sys.argv[2]) if len(sys.argv) > 2 else 256):
    print(image_id, photo.shape, render.shape, depth.shape, float((render[..., 3] > 0).mean()))
