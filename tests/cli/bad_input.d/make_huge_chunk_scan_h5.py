"""Writes PATH: DXchange projections, /exchange/data of 4 views of 4x4
float32 zeros (line integrals) and /exchange/theta, the data stored in one
gzip chunk of CHUNK_MIB MiB of zeros (a few hundred KB of file), which
libhdf5 inflates whole to read a row. The chunk is compressed here 64 MiB at
a time and written as it is (write_direct_chunk), never held whole."""
import sys
import zlib

import h5py
import numpy as np

path, chunk_mib = sys.argv[1], int(sys.argv[2])
views = chunk_mib // 4  # chunks of views x 1024 x 256 float32 = chunk_mib MiB
with h5py.File(path, "w") as f:
    data = f.create_dataset("exchange/data", shape=(4, 4, 4), maxshape=(None, None, None), dtype="<f4",
                            chunks=(views, 1024, 256), compression="gzip")
    f.create_dataset("exchange/theta", data=np.array([0.0, 90.0, 180.0, 270.0]))
    deflate = zlib.compressobj(1)
    zeros = bytes(1 << 20)
    parts = [deflate.compress(zeros) for _ in range(chunk_mib)]
    parts.append(deflate.flush())
    data.id.write_direct_chunk((0, 0, 0), b"".join(parts))
