"""numpy basic indexing of a 3-D volume, turned into one box to read.

A key (integers, slices with any step, Ellipsis, None) becomes the smallest
box [lo, hi) per axis that holds every selected voxel, and a key that picks
the selection out of that box once it is read. Axes are in numpy order
(z, y, x). Anything else (boolean or integer arrays) is refused: those are
advanced indexing, which would read arbitrary voxels.
"""

import operator

import numpy as np


def _expand(key, ndim):
    if not isinstance(key, tuple):
        key = (key,)
    ellipses = sum(1 for k in key if k is Ellipsis)
    if ellipses > 1:
        raise IndexError("an index can only have a single ellipsis ('...')")
    axes = sum(1 for k in key if k is not None and k is not Ellipsis)
    if axes > ndim:
        raise IndexError(f"too many indices for a volume: {ndim} dimensions, {axes} indexed")
    out = []
    for k in key:
        if k is Ellipsis:
            out.extend([slice(None)] * (ndim - axes))
        else:
            out.append(k)
    if not ellipses:
        out.extend([slice(None)] * (ndim - axes))
    return out


def plan(key, shape):
    """(lo, hi, local_key, empty_shape) for `key` on a volume of `shape`.

    lo and hi are per axis in numpy order; local_key indexes the array read
    for [lo, hi). empty_shape is the result's shape when it selects no voxel
    (nothing is read then), else None.
    """
    lo, hi, local, result_shape = [], [], [], []
    empty = False
    axis = 0
    for k in _expand(key, len(shape)):
        if k is None:
            local.append(None)
            result_shape.append(1)
            continue
        n = shape[axis]
        if isinstance(k, slice):
            r = range(*k.indices(n))
            result_shape.append(len(r))
            if len(r) == 0:
                empty = True
                lo.append(0)
                hi.append(0)
                local.append(slice(0, 0))
            else:
                first, last = min(r[0], r[-1]), max(r[0], r[-1])
                lo.append(first)
                hi.append(last + 1)
                stop = r[-1] - first + (1 if r.step > 0 else -1)
                local.append(slice(r[0] - first, stop if stop >= 0 else None, r.step))
        else:
            try:
                # numpy reads a bool as a mask (advanced indexing), not as 0 or 1.
                if isinstance(k, (bool, np.bool_)):
                    raise TypeError
                i = operator.index(k)
            except TypeError:
                raise IndexError(
                    "only integers, slices (':'), ellipsis ('...') and None are valid indices "
                    f"of an ivol volume, not {type(k).__name__}"
                ) from None
            if not -n <= i < n:
                raise IndexError(f"index {i} is out of bounds for axis {axis} with size {n}")
            i %= n
            lo.append(i)
            hi.append(i + 1)
            local.append(0)
        axis += 1
    return lo, hi, tuple(local), (tuple(result_shape) if empty else None)
