#!/usr/bin/env python3
"""Read an nrw-etl dataset with no Rust: pyarrow and DuckDB for the tables, OpenEXR for
depth, Pillow for PNG payloads.

    python3 tests/oracles/read_shards.py DATASET

Checks, independently of the Rust code, that every kept view's payloads match the CRC-32
written beside them (zlib's), decode, and agree with each other and with the tables, and
that every descriptor matches its CRC-32; prints one JSON line of counts. Used by the test
`shards_read_back_with_pyarrow_duckdb_and_openexr` (tests/cli.rs).
"""
import io
import json
import sys
import zlib
from pathlib import Path

import duckdb
import numpy as np
import OpenEXR
import pyarrow.parquet as pq
from PIL import Image


def png(b):
    img = Image.open(io.BytesIO(b))
    assert img.format == "PNG", img.format
    return np.asarray(img)


def exr_depth(b):
    f = OpenEXR.File(io.BytesIO(b)) if hasattr(OpenEXR, "File") else None
    if f is not None:
        ch = f.channels()
        z = ch["Z"].pixels
        return np.asarray(z, dtype=np.float32)
    raise RuntimeError("OpenEXR >= 3.3 with OpenEXR.File is required")


PAYLOADS = ["photo_png", "color_png", "depth_exr", "normal_png", "semantics_png", "transient_png", "labels_png"]


def check_crcs(row, where):
    """Each payload's CRC-32 (zlib's) equals the one written beside it; null with null."""
    for c in PAYLOADS:
        data, crc = row[c], row[c + "_crc32"]
        assert (data is None) == (crc is None), (where, c)
        if data is not None:
            assert zlib.crc32(data) == crc, (where, c, zlib.crc32(data), crc)


def main(root):
    root = Path(root)
    manifest = json.loads((root / "manifest.json").read_text())
    shards = [t["path"] for t in manifest["tables"] if t["path"].startswith("shards/")]
    images = pq.read_table(root / "scene/images.parquet")
    # DuckDB reads the same Parquet files on its own.
    con = duckdb.connect()
    kept_sql = con.execute(
        f"SELECT count(*) FROM read_parquet('{root / 'scene/images.parquet'}') WHERE verdict = 'kept'"
    ).fetchone()[0]
    rows_sql = 0
    if shards:
        files = ", ".join(f"'{root / s}'" for s in shards)
        rows_sql = con.execute(f"SELECT count(*) FROM read_parquet([{files}])").fetchone()[0]
    assert kept_sql == rows_sql, (kept_sql, rows_sql)
    checked = 0
    for s in shards:
        t = pq.read_table(root / s).to_pylist()
        for i, row in enumerate(t):
            check_crcs(row, f"{s} row {i}")
            w, h = row["width"], row["height"]
            photo, color = png(row["photo_png"]), png(row["color_png"])
            assert photo.shape == (h, w, 3), photo.shape
            assert color.shape == (h, w, 4), color.shape
            z = exr_depth(row["depth_exr"])
            assert z.shape == (h, w), z.shape
            assert np.array_equal(color[:, :, 3] == 255, z > 0), "alpha must equal depth coverage"
            empty = float((z <= 0).mean())
            assert abs(empty - row["empty_ratio"]) < 1e-9, (empty, row["empty_ratio"])
            checked += 1
    # Descriptors: CRC-32 of the values as little-endian float32.
    descriptors = 0
    for t in manifest["tables"]:
        if t["path"].startswith("descriptors/part-"):
            for i, row in enumerate(pq.read_table(root / t["path"]).to_pylist()):
                raw = np.asarray(row["descriptor"], dtype="<f4").tobytes()
                assert zlib.crc32(raw) == row["descriptor_crc32"], (t["path"], i)
                descriptors += 1
    print(json.dumps({"images": images.num_rows, "kept": kept_sql, "shard_rows": rows_sql, "views_checked": checked, "descriptors_checked": descriptors}))


if __name__ == "__main__":
    main(sys.argv[1])
