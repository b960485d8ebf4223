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



# Along y and x, selected voxels further apart than this are read as boxes of
# their own: blocks hold cubes of about 16 voxels a side, so a gap of two
# blocks saves decoding at least one. Along z a step reads planes one by one.
SPLIT_GAP = 32
# Past this many boxes a read costs more in calls than it saves in decoding:
# y and x are then read as one box around the selection.
MAX_BOXES = 4096


def _selected(k, n):
    """The indices an axis key selects, in output order, as a range."""
    if isinstance(k, slice):
        return range(*k.indices(n))
    i = operator.index(k) % n
    return range(i, i + 1)


def _runs(indices, split_any_step):
    """Pieces of one axis' selection: (first output position, count, indices)."""
    step = abs(indices.step)
    if len(indices) <= 1 or step == 1 or (not split_any_step and step <= SPLIT_GAP):
        return [(0, len(indices), indices)]
    return [(p, 1, indices[p : p + 1]) for p in range(len(indices))]


def pieces(key, shape):
    """The boxes to read for a key that plan() accepted and that selects at
    least one voxel: (out_shape, squeeze_key, boxes), each box
    (lo, hi, out_slices, box_slices): read [lo, hi), take box[box_slices]
    into out[out_slices]. out has the (z, y, x) selection's shape; out[squeeze_key]
    drops integer axes and adds None axes. Axes in numpy order.
    """
    expanded = _expand(key, len(shape))
    squeeze = tuple(None if k is None else slice(None) if isinstance(k, slice) else 0 for k in expanded)
    selected = [_selected(k, n) for k, n in zip((k for k in expanded if k is not None), shape)]
    runs = [_runs(selected[0], True)] + [_runs(s, False) for s in selected[1:]]
    if len(runs[0]) * len(runs[1]) * len(runs[2]) > MAX_BOXES:
        runs = [runs[0]] + [[(0, len(s), s)] for s in selected[1:]]
    boxes = []
    for rz in runs[0]:
        for ry in runs[1]:
            for rx in runs[2]:
                lo, hi, out_slices, box_slices = [], [], [], []
                for first, count, idx in (rz, ry, rx):
                    low = min(idx[0], idx[-1])
                    lo.append(low)
                    hi.append(max(idx[0], idx[-1]) + 1)
                    out_slices.append(slice(first, first + count))
                    stop = idx[-1] - low + (1 if idx.step > 0 else -1)
                    box_slices.append(slice(idx[0] - low, stop if stop >= 0 else None, idx.step))
                boxes.append((lo, hi, tuple(out_slices), tuple(box_slices)))
    return tuple(len(s) for s in selected), squeeze, boxes
