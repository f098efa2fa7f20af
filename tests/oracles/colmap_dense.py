"""COLMAP's own reading and writing of dense-workspace maps, to check ours against.

With NRW_COLMAP_SCRIPTS naming COLMAP's scripts/python folder (.ci/run takes it from Debian's
colmap 3.8 source tarball, checked by its SHA-256), COLMAP's read_write_dense.py itself is
imported and run, unmodified. Without it, this file's transcription stands in; it follows scripts/python/read_write_dense.py of COLMAP (3.8; the same in 3.9–3.11) line by
line: `read_array` (its lines 38–53: the header's three numbers before the third `&`, then
`np.fromfile(float32).reshape((width, height, channels), order="F")` transposed to
height × width × channels and squeezed) and `write_array` (lines 56–82: the header, then the
array transposed to width × height × channels and flattened in Fortran order, packed `<f`).

usage: colmap_dense.py read FILE EXPECTED.npy   (exit 0 when COLMAP's reading equals it)
       colmap_dense.py write OUT FROM.npy       (COLMAP's writing of the array)
Prints which reader ran: "reader: colmap PATH" or "reader: transcription".
"""

import os

import struct
import sys

import numpy as np


def read_array(path):
    with open(path, "rb") as fid:
        width, height, channels = np.genfromtxt(
            fid, delimiter="&", max_rows=1, usecols=(0, 1, 2), dtype=int
        )
        fid.seek(0)
        ampersands = 0
        byte = fid.read(1)
        while True:
            if byte == b"&":
                ampersands += 1
                if ampersands >= 3:
                    break
            byte = fid.read(1)
        array = np.fromfile(fid, np.float32)
    array = array.reshape((width, height, channels), order="F")
    return np.transpose(array, (1, 0, 2)).squeeze()


def write_array(array, path):
    assert array.dtype == np.float32
    if array.ndim == 2:
        height, width = array.shape
        channels = 1
        flipped = np.transpose(array, (1, 0))
    else:
        height, width, channels = array.shape
        flipped = np.transpose(array, (1, 0, 2))
    with open(path, "w") as fid:
        fid.write(f"{width}&{height}&{channels}&")
    values = flipped.reshape(-1, order="F").tolist()
    with open(path, "ab") as fid:
        fid.write(struct.pack("<" + "f" * len(values), *values))


if __name__ == "__main__":
    scripts = os.environ.get("NRW_COLMAP_SCRIPTS")
    if scripts:
        sys.path.insert(0, scripts)
        import read_write_dense

        read_array, write_array = read_write_dense.read_array, read_write_dense.write_array
        print("reader: colmap", os.path.realpath(read_write_dense.__file__))
    else:
        print("reader: transcription")
    what, path, npy = sys.argv[1:4]
    if what == "read":
        got, want = read_array(path), np.load(npy)
        if got.shape != want.shape or not np.array_equal(got, want):
            sys.exit(f"COLMAP reads {got.shape} {got.ravel()[:8]}, expected {want.shape} {want.ravel()[:8]}")
    else:
        write_array(np.load(npy), path)
