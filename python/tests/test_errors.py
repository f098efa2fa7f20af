"""Damaged and foreign datasets are refused by name: a flipped byte in any payload column
names the shard file, row and column; another schema version names both versions."""

import json
import shutil

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import nrw
import reference


def flip_one_byte(shard, column, row):
    """Rewrite `shard` with one bit of one payload flipped; its CRC column left as written."""
    table = pq.read_table(shard)
    values = table.column(column).to_pylist()
    damaged = bytearray(values[row])
    damaged[len(damaged) // 2] ^= 0x10
    values[row] = bytes(damaged)
    i = table.schema.get_field_index(column)
    table = table.set_column(i, table.schema.field(i), pa.array(values, table.schema.field(i).type))
    # The dataset's layout: row groups of 8 rows, zstd pages.
    pq.write_table(table, shard, row_group_size=8, compression="zstd")


@pytest.mark.parametrize("column", reference.PAYLOADS)
def test_a_flipped_byte_in_any_payload_names_file_row_and_column(demo, tmp_path, column):
    copy = tmp_path / "ds"
    shutil.copytree(demo, copy)
    shard = reference.shard_paths(str(copy))[0]
    rows = pq.read_table(shard).to_pylist()
    row = len(rows) - 2
    assert rows[row][column] is not None, f"the demo has {column}"
    flip_one_byte(shard, column, row)
    image_id = rows[row]["image_id"]
    ds = nrw.Dataset(copy)
    expected = rf"{shard}: record row {row} \(image {image_id}\): field `{column}`: CRC-32"
    with pytest.raises(nrw.DatasetError, match=expected):
        for _ in ds.views():
            pass
    with pytest.raises(nrw.DatasetError, match=expected):
        ds.get(image_id)
    # Views of other row groups still read.
    assert ds.get(rows[0]["image_id"])["image_id"] == rows[0]["image_id"]


def test_another_schema_version_is_refused_by_name(demo, tmp_path):
    copy = tmp_path / "ds"
    shutil.copytree(demo, copy)
    manifest = copy / "manifest.json"
    data = json.loads(manifest.read_text())
    assert data["schema_version"] == nrw.SCHEMA_VERSION
    data["schema_version"] = nrw.SCHEMA_VERSION + 1
    manifest.write_text(json.dumps(data))
    with pytest.raises(nrw.DatasetError) as e:
        nrw.Dataset(copy)
    message = str(e.value)
    assert f"schema version {nrw.SCHEMA_VERSION + 1} is not the {nrw.SCHEMA_VERSION}" in message
    assert str(copy) in message
