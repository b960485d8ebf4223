#!/usr/bin/env python3
"""Writes the seed recipes of fuzz_vdb_grid.cpp into tests/fuzz/regressions/vdb-grid/.

A recipe (read by the harness's Recipe class, little-endian): background
(float32 bits), grid name (u16 length + bytes), saveFloatAsHalf (u8),
transform (u8 mode; mode 1: scale x, y, z and translation x, y, z as
float64), metadata strings (u8 mask: unit, quantity, value_unit, provenance,
then each present one as u16 length + bytes), then up to 16 steps: kind (u8:
% 5 = 0 set on, 1 set off, 2 tile at level 1 + (kind >> 3) % 3, 3 fill a box,
4 set active state; bit 5 = active), a coordinate (per axis: u8 anchor index
[0, INT_MIN, INT_MAX, -4096, 4096, 2^30, -2^30, INT_MIN + 4096, INT_MAX - 4095]
then an i16 offset), a value (float32 bits), and for a box three u8 extents.
"""
import pathlib
import struct

ANCHOR = {0: 0, "min": 1, "max": 2, "4096": 4, "top": 8}


def text(s):
    b = s.encode()
    return struct.pack("<H", len(b)) + b


def coord(anchor, dx, dy, dz):
    a = ANCHOR[anchor]
    return b"".join(struct.pack("<Bh", a, d) for d in (dx, dy, dz))


def step(kind, anchor, d, value, extents=None):
    out = struct.pack("<B", kind) + coord(anchor, *d) + struct.pack("<f", value)
    if extents:
        out += bytes(extents)
    return out


def header(name, background=0.0, half=0, scale=None, strings=()):
    out = struct.pack("<f", background) + text(name) + bytes([half])
    if scale is None:
        out += bytes([0])
    else:
        out += bytes([1]) + struct.pack("<6d", *scale)
    mask = 0
    body = b""
    for bit, s in strings:
        mask |= 1 << bit
        body += text(s)
    return out + bytes([mask]) + body


ON, OFF, TILE1, FILL, STATE = 0, 1, 2, 3, 4
ACTIVE = 1 << 5
seeds = {
    "seed-small": header("density", 0.0, 0, (0.5, 0.5, 0.5, 1, 2, 3),
                         [(0, "mm"), (1, "attenuation"), (2, "1/mm"), (3, '{"voxel_size_known": true}')])
    + step(ON, 0, (3, 4, 5), 1.0) + step(FILL | ACTIVE, 0, (8, 8, 8), 2.5, (20, 3, 9))
    + step(TILE1 | ACTIVE, 0, (16, 0, 0), 3.0) + step(OFF, 0, (1, 1, 1), -0.0),
    "seed-int-min": header("low", 1.0) + step(ON, "min", (0, 0, 0), 7.0) + step(ON, "min", (5, 9, 2), 8.0)
    + step(TILE1 | ACTIVE, "min", (8, 8, 8), 9.0),
    "seed-int-max": header("high", -1.0) + step(ON, "max", (0, 0, 0), float("nan"))
    + step(OFF, "max", (-1, 0, 0), 4.0) + step(ON, "top", (0, 0, 0), 5.0),
    "seed-span-2e31": header("wide") + step(ON, 0, (0, 0, 0), 1.0) + step(ON, "max", (0, 0, 0), 1.0),
    "seed-unknown-size": header("unknown", 0.0, 1, None, [(3, '{"voxel_size_known": false}')])
    + step(FILL | ACTIVE, "4096", (0, 0, 0), 0.25, (9, 9, 9)),
}
folder = pathlib.Path(__file__).resolve().parent / "regressions" / "vdb-grid"
folder.mkdir(parents=True, exist_ok=True)
for name, data in seeds.items():
    (folder / name).write_bytes(data)
