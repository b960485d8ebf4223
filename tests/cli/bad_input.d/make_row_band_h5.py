"""Writes the HDF5 inputs of hdf5_row_bands.sh into DIR.

Small (3 x 2500 x 3000 u16, 15 MB a slice; the hash pattern of
row_bands.sh), one per layout, each with chunks that bands of 640 rows cut
through: contiguous big-endian (HDF5 converts on the way), gzip with shuffle
in chunks of 2 x 100 x 300 (deeper than a slice, bands end inside them),
blosc in chunks of 3 x 128 x 512.

Large (2 x 16384 x 16384 u8, 256 MiB a slice): zeros but for rows of a
pattern that cross the readers' band boundaries (rows 1000-1099 of slice 0,
the last 37 rows of slice 1), written a strip at a time so that every chunk
is stored (no chunk left to the fill value): gzip in 1 x 256 x 1024 chunks,
blosc in 1 x 512 x 512 chunks, contiguous (a sparse file: the zeros are
holes); and one slice stored as a single gzip chunk, which libhdf5 can only
inflate whole.

    python3 make_row_band_h5.py DIR
"""
import sys

import h5py
import numpy as np

BLOSC = 32001
BLOSC_LZ4_SHUFFLE = (0, 0, 0, 0, 5, 1, 1)
SIDE = 16384


def small():
    n = 3 * 2500 * 3000
    return (np.arange(n, dtype=np.uint64) * 2654435761 % 65521).astype(np.uint16).reshape(3, 2500, 3000)


def big_rows(z, y0, y1):
    """Rows y0..y1 of slice z of the large volume."""
    rows = np.zeros((y1 - y0, SIDE), np.uint8)
    marked = [(1000, 1100)] if z == 0 else [(SIDE - 37, SIDE)]
    x = np.arange(SIDE, dtype=np.uint64)
    for a, b in marked:
        for y in range(max(a, y0), min(b, y1)):
            rows[y - y0] = ((x * 7 + y * 13 + z * 101) % 251 + 1).astype(np.uint8)
    return rows


def write_big(path, **layout):
    with h5py.File(path, "w") as f:
        d = f.create_dataset("/exchange/data", shape=(2, SIDE, SIDE), dtype="u1", **layout)
        strip = 1024
        for z in range(2):
            for y in range(0, SIDE, strip):
                rows = big_rows(z, y, y + strip)
                if layout or rows.any():  # contiguous: leave the zeros as holes
                    d[z, y:y + strip, :] = rows


def main(folder):
    v = small()
    with h5py.File(folder + "/contiguous.h5", "w") as f:
        f.create_dataset("/exchange/data", data=v, dtype=">u2")
    with h5py.File(folder + "/gzip.h5", "w") as f:
        f.create_dataset("/exchange/data", data=v, chunks=(2, 100, 300), compression="gzip", shuffle=True)
    with h5py.File(folder + "/blosc.h5", "w") as f:
        f.create_dataset("/exchange/data", data=v, chunks=(3, 128, 512), compression=BLOSC,
                         compression_opts=BLOSC_LZ4_SHUFFLE)
    write_big(folder + "/big-gzip.h5", chunks=(1, 256, 1024), compression="gzip")
    write_big(folder + "/big-blosc.h5", chunks=(1, 512, 512), compression=BLOSC, compression_opts=BLOSC_LZ4_SHUFFLE)
    write_big(folder + "/big-contiguous.h5")
    with h5py.File(folder + "/big-one-chunk.h5", "w") as f:
        f.create_dataset("/exchange/data", shape=(1, SIDE, SIDE), dtype="u1", chunks=(1, SIDE, SIDE),
                         compression="gzip")[0, :1, :] = 1


if __name__ == "__main__":
    main(sys.argv[1])
