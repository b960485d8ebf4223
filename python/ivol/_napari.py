"""The napari reader contribution (napari.yaml, npe2): an .ivol file opens as
one multiscale image, its levels of detail the pyramid, with the voxel size
as scale and the origin as translate, all in (z, y, x).

Imports nothing of napari: napari calls get_reader with a path and the
reader it returns with the same path (or a list of paths).
"""

import os

import numpy as np

from . import open as _open

# The level napari's contrast is taken from: the finest one of at most this
# many voxels, read whole once when the file is opened.
CONTRAST_LEVEL_VOXELS = 1 << 21


def contrast_limits(f):
    """[low, high] of the values, from the finest level of at most
    CONTRAST_LEVEL_VOXELS voxels: napari takes a multiscale image's limits
    from its coarsest level (one voxel here: a blank view) or [0, 1]."""
    for k in range(f.levels):
        level = f.level(k)
        if int(np.prod(level.shape)) <= CONTRAST_LEVEL_VOXELS:
            values = np.asarray(level[...], dtype=np.float64)
            finite = values[np.isfinite(values)]
            if finite.size == 0:
                return [0.0, 1.0]
            low, high = float(finite.min()), float(finite.max())
            return [low, high] if high > low else [low, low + 1.0]
    return [0.0, 1.0]


def get_reader(path):
    """The reader for `path` when it is one .ivol file, else None (napari then
    asks other plugins)."""
    if isinstance(path, (list, tuple)):
        if len(path) != 1:
            return None
        path = path[0]
    path = os.fspath(path)
    if not path.endswith(".ivol") or not os.path.isfile(path):
        return None
    return read_layers


def read_layers(path):
    """[(pyramid, layer options, "image")] for napari: the pyramid is
    [f.level(k) for k in range(f.levels)], finest first; level k's voxels are
    2^k voxels of level 0 wide, which napari derives from the shapes, so one
    scale (the voxel size) serves every level."""
    if isinstance(path, (list, tuple)):
        path = path[0]
    f = _open(path)
    pyramid = [f.level(k) for k in range(f.levels)]
    options = {
        "name": os.path.splitext(os.path.basename(f.path))[0],
        "scale": f.voxel_size or (1.0, 1.0, 1.0),  # unknown: voxels as units
        "translate": f.origin,
        "metadata": {"ivol": f.metadata, "unit": f.unit},
        "multiscale": len(pyramid) > 1,
        "contrast_limits": contrast_limits(f),
    }
    # A file of one level (a volume of one voxel) is a plain image to napari.
    data = pyramid if len(pyramid) > 1 else pyramid[0]
    return [(data, options, "image")]
