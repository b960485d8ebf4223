"""Writing numpy arrays as .ivol files: as a lossless octree (write, the
file `ivol convert` writes) or as one of the structures of spec §8 / §8A
generated from a mask of where full resolution is needed (write_structure,
what `ivol recon --structure` writes)."""

import json
import os

import numpy as np

from . import _ivol
from ._errors import InvalidArgumentError

_SAMPLE_NAMES = {
    np.dtype(np.uint8): "u8",
    np.dtype(np.uint16): "u16",
    np.dtype(np.int16): "i16",
    np.dtype(np.float16): "f16",
    np.dtype(np.float32): "f32",
}


def _voxel_size_or_unknown(voxel_size, provenance):
    """(vz, vy, vx, provenance): a voxel size not given is recorded as
    unknown, as `ivol convert` records it (1 in the metadata, provenance
    "voxel_size_known": false), never as a size nobody measured."""
    if voxel_size is not None:
        vz, vy, vx = (float(v) for v in voxel_size)
        return vz, vy, vx, provenance
    return 1.0, 1.0, 1.0, dict(provenance or {}, voxel_size_known=False)


def write(
    path,
    array,
    voxel_size=None,
    origin=(0.0, 0.0, 0.0),
    unit="mm",
    encoding=None,
    quantity=None,
    value_unit=None,
    provenance=None,
    block_bytes=0,
    byte_planes=True,
):
    """Writes a 3-D array (z, y, x) as a lossless octree .ivol file, as
    `ivol convert --structure octree` writes the same samples from a raw
    file: the same file, byte for byte, given the same provenance. voxel_size
    and origin are in (z, y, x) order; without voxel_size the file says the
    voxel size is unknown (File.voxel_size is then None). encoding: None (lossless: uint16 for integer arrays,
    binary16 for float16, float32 for float32), "uint16", "binary16" or
    "float32". provenance: a dict merged into the default provenance.
    The file appears at `path` only when complete."""
    a = np.asarray(array)
    if a.ndim != 3:
        raise InvalidArgumentError(f"{path}: a volume needs 3 dimensions (z, y, x), not {a.ndim}", "invalid-argument")
    name = _SAMPLE_NAMES.get(a.dtype.newbyteorder("="))
    if name is None:
        raise InvalidArgumentError(
            f"{path}: samples of type {a.dtype} cannot be written; use uint8, uint16, int16, float16 or float32 "
            "(e.g. array.astype(numpy.float32))",
            "invalid-argument",
        )
    a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
    if 0 in a.shape:
        raise InvalidArgumentError(f"{path}: the volume is empty {a.shape}", "invalid-argument")
    vz, vy, vx, provenance = _voxel_size_or_unknown(voxel_size, provenance)
    oz, oy, ox = (float(v) for v in origin)
    return _ivol.write(
        os.fspath(path),
        a,
        name,
        (a.shape[2], a.shape[1], a.shape[0]),
        encoding or "",
        (vx, vy, vz),
        (ox, oy, oz),
        unit,
        quantity or "",
        value_unit or "",
        json.dumps(provenance) if provenance else "",
        int(block_bytes),
        bool(byte_planes),
    )


def write_structure(
    path,
    array,
    need,
    factor=1,
    structure="regular",
    voxel_size=None,
    origin=(0.0, 0.0, 0.0),
    unit="mm",
    encoding="float32",
    quantity=None,
    value_unit=None,
    provenance=None,
    nested_cell=16,
    rectilinear_max_interval=64,
    block_bytes=0,
):
    """Writes a 3-D array (z, y, x) as a structure: "octree", "regular",
    "rectilinear" or "nested" (spec §8, §8A). `need` is a boolean array of
    cells `factor` voxels a side (a power of two), shape ceil(shape / factor)
    (z, y, x): full resolution wherever a cell needs it, coarse voxels
    elsewhere as the structure allows (libformat's generate_structure, as
    `ivol recon --structure` uses it), each coarse voxel the mean of the
    voxels it covers. encoding: "float32" or "binary16". nested_cell: the
    nested grid's cell edge (a power of two); rectilinear_max_interval: the
    rectilinear grid's widest interval outside the needed ranges. Returns
    file_bytes, max_abs_error (of the stored values against those means),
    structure_voxels and encoding. The file appears at `path` only when
    complete."""
    a = np.asarray(array)
    m = np.asarray(need)
    if a.ndim != 3 or m.ndim != 3:
        raise InvalidArgumentError(
            f"{path}: array and need need 3 dimensions (z, y, x), not {a.ndim} and {m.ndim}", "invalid-argument"
        )
    if 0 in a.shape:
        raise InvalidArgumentError(f"{path}: the volume is empty {a.shape}", "invalid-argument")
    if not (a.dtype.kind in "ui" and a.dtype.itemsize <= 2 or a.dtype.kind == "f" and a.dtype.itemsize <= 4):
        raise InvalidArgumentError(
            f"{path}: samples of type {a.dtype} cannot be written as a structure; use uint8, uint16, int8, int16, "
            "float16 or float32 (e.g. array.astype(numpy.float32))",
            "invalid-argument",
        )
    factor = int(factor)
    if factor < 1 or factor & (factor - 1):
        raise InvalidArgumentError(f"{path}: factor {factor} is not a power of two", "invalid-argument")
    nested_cell = int(nested_cell)
    if nested_cell < 1 or nested_cell & (nested_cell - 1):
        raise InvalidArgumentError(f"{path}: nested_cell {nested_cell} is not a power of two", "invalid-argument")
    vz, vy, vx, provenance = _voxel_size_or_unknown(voxel_size, provenance)
    oz, oy, ox = (float(v) for v in origin)
    return _ivol.write_grid(
        os.fspath(path),
        np.ascontiguousarray(a, dtype=np.float32),
        structure,
        np.ascontiguousarray(m != 0, dtype=np.uint8),
        factor,
        nested_cell,
        int(rectilinear_max_interval),
        encoding,
        (vx, vy, vz),
        (ox, oy, oz),
        unit,
        quantity or "",
        value_unit or "",
        json.dumps(provenance) if provenance else "",
        int(block_bytes),
    )
