#!/usr/bin/env python3
"""A raw little-endian u16 volume N^3 for the temporary-disk bench: a ball
(and a smaller dense one inside) in air, with Gaussian noise of sigma 20 on
every voxel, so a lossless file cannot merge leaves. Usage: N OUT.raw"""
import array
import math
import os
import random
import sys

n = int(sys.argv[1])
rng = random.Random(23)
noise = array.array("h", (int(round(rng.gauss(0.0, 20.0))) for _ in range(65536)))
c = (n - 1) / 2.0
with open(sys.argv[2], "wb") as out:
    for z in range(n):
        row_noise = array.array("H", os.urandom(2 * n * n))
        plane = array.array("H", bytes(2 * n * n))
        for y in range(n):
            for x in range(n):
                r = math.sqrt((x - c) ** 2 + (y - c) ** 2 + (z - c) ** 2)
                base = 300 if r > 0.4 * n else (2000 if r > 0.2 * n else 3500)
                plane[y * n + x] = base + noise[row_noise[y * n + x]]
        out.write(plane.tobytes())
