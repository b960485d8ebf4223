#!/usr/bin/env python3
"""Writes the NXtomo fixtures of tests/cli/run_scan_formats.sh with the
`nxtomo` package (ESRF's NXtomo writer, `pip install nxtomo`), not with ivol.

    python3 -m venv /tmp/nxvenv && /tmp/nxvenv/bin/pip install nxtomo
    IVOL=build/tools/ivol /tmp/nxvenv/bin/python tests/data/nxtomo/make_fixtures.py

The scan is ivol's Shepp-Logan phantom (`ivol phantom`, RTK geometry in
scan.xml, line integrals scaled to at most 2.5 in scan.raw, float32, both
kept here as the reference), turned
into the detector counts a scanner records: a dark current D and a flat
field F that differ per pixel, I = D + (F - D)·exp(-p) rounded to uint16.
The frames are what a beamline writes: 2 darks, 2 flats, the first half of
the projections, one frame marked invalid (image key 3, all zeros: it must
be skipped), the other half, 2 flats again. The flats before the scan are
2 % darker than F and those after 2 % brighter, so only their mean gives F.
Units differ on purpose: x pixel size in metres, y in millimetres, the
distances in metres.
"""
import os
import subprocess

import numpy as np
import pint
from nxtomo import NXtomo
from nxtomo.nxobject.nxdetector import ImageKey

here = os.path.dirname(os.path.abspath(__file__))
ivol = os.environ["IVOL"]
views, columns, rows, sid, sdd, pitch = 20, 32, 16, 300.0, 600.0, 2.0
subprocess.run([ivol, "-q", "phantom", "shepp-logan", "--views", str(views), "--detector", f"{columns},{rows}",
                "--sid", str(sid), "--sdd", str(sdd), "--pitch", str(pitch), "--radius", "12", "-f",
                "-o", os.path.join(here, "scan.raw"), "--geometry-out", os.path.join(here, "scan.xml")], check=True)
# The phantom's line integrals reach 24 (its densities are per mm); a scanner
# would see no photons through that. Scaled to at most 2.5, still line
# integrals, and kept as the raw reference.
p = np.fromfile(os.path.join(here, "scan.raw"), "<f4").reshape(views, rows, columns)
p = (p * np.float32(2.5 / p.max())).astype("<f4")
p.tofile(os.path.join(here, "scan.raw"))
p = p.astype(np.float64)

v, u = np.mgrid[0:rows, 0:columns]
flat = 40000.0 + 3000.0 * np.cos(u / 7.0) + 1500.0 * np.sin(v / 5.0)
dark = 200.0 + 20.0 * ((u + 2 * v) % 5)
counts = lambda image: np.clip(np.rint(image), 0, 65535).astype(np.uint16)
projections = counts(dark + (flat - dark) * np.exp(-p))
angles = 360.0 / views * np.arange(views)  # ivol phantom's angles: RTK's, first 0

D, F, P, X = ImageKey.DARK_FIELD, ImageKey.FLAT_FIELD, ImageKey.PROJECTION, ImageKey.INVALID
half = views // 2
frames = ([counts(dark)] * 2 + [counts(0.98 * flat)] * 2 + list(projections[:half]) +
          [np.zeros((rows, columns), np.uint16)] + list(projections[half:]) + [counts(1.02 * flat)] * 2)
keys = [D, D, F, F] + [P] * half + [X] + [P] * (views - half) + [F, F]
frame_angles = [0.0] * 4 + list(angles[:half]) + [999.0] + list(angles[half:]) + [360.0] * 2

u_ = pint.get_application_registry()
scan = NXtomo()
scan.instrument.detector.data = np.stack(frames)
scan.instrument.detector.image_key_control = keys
scan.sample.rotation_angle = np.asarray(frame_angles) * u_.degree
scan.instrument.detector.x_pixel_size = pitch * 1e-3 * u_.m
scan.instrument.detector.y_pixel_size = pitch * u_.mm
scan.instrument.detector.distance = (sdd - sid) * 1e-3 * u_.m
scan.instrument.source.distance = sid * 1e-3 * u_.m
scan.save(os.path.join(here, "shepp_logan.nx"), data_path="entry0000", overwrite=True)

# The same scan as a synchrotron's parallel-beam file: no source distance.
scan.instrument.source.distance = None
scan.save(os.path.join(here, "parallel.nx"), data_path="entry0000", overwrite=True)
