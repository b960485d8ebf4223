"""Writes PATH: a 4x4x4 uint8 dataset /data stored in one 2 GiB gzip chunk
of zeros (about 9 MB of file), which libhdf5 inflates whole to read it.
The chunk is compressed here, 64 MiB at a time, and written as it is
(write_direct_chunk), so that making the file never holds 2 GiB."""
import sys
import zlib

import h5py

path = sys.argv[1]
chunk = (2048, 1024, 1024)  # 2 GiB of uint8; HDF5 allows up to 4 GiB - 1
with h5py.File(path, "w") as f:
    data = f.create_dataset("data", shape=(4, 4, 4), maxshape=(None, None, None), dtype="u1", chunks=chunk,
                            compression="gzip")
    deflate = zlib.compressobj(1)
    zeros = bytes(64 << 20)
    parts = [deflate.compress(zeros) for _ in range(32)]
    parts.append(deflate.flush())
    data.id.write_direct_chunk((0, 0, 0), b"".join(parts))
