"""The napari reader plugin (python/ivol/napari.yaml, ivol._napari).

Without napari (ctest python_napari_reader, Debian's /usr/bin/python3): the
manifest names a function that exists, and the reader it returns gives the
levels of detail as a pyramid whose levels are the means of 2^k cubes of the
written array (a dense float64 reference), with the voxel size as scale.

With IVOL_NAPARI=1 (ctest python_napari_viewer, registered only when CMake is
given IVOL_NAPARI_PYTHON, an interpreter that has napari and npe2): napari's
viewer model opens the file through the plugin as a multiscale image layer
and slices it; where a display is there (DISPLAY, e.g. under xvfb-run: Qt's
offscreen platform gives vispy no OpenGL context) the Qt viewer itself opens
it and its canvas shows the slice, not a blank picture.

PYTHONPATH=<build>/python.
"""

import importlib
import os
import tempfile
import unittest

import numpy as np

import ivol
from ivol import _napari

PACKAGE_DIR = os.path.dirname(ivol.__file__)
WITH_NAPARI = os.environ.get("IVOL_NAPARI") == "1"


def block_means(a, k):
    """Level k of spec §12.3 from the full array, in float64: each voxel the
    mean of the 2^k cube it covers (dims here are multiples of 2^k)."""
    s = 1 << k
    z, y, x = (n // s for n in a.shape)
    return a.astype(np.float64).reshape(z, s, y, s, x, s).mean(axis=(1, 3, 5))


class Volume:
    def __enter__(self):
        self.tmp = tempfile.TemporaryDirectory()
        rng = np.random.default_rng(11)
        self.array = rng.normal(size=(32, 48, 64)).astype(np.float32)
        self.path = os.path.join(self.tmp.name, "part.ivol")
        ivol.write(self.path, self.array, voxel_size=(0.5, 0.25, 0.125), origin=(3, 2, 1), unit="mm")
        return self

    def __exit__(self, *exc):
        self.tmp.cleanup()


class Reader(unittest.TestCase):
    def test_manifest_names_the_reader(self):
        import yaml

        with open(os.path.join(PACKAGE_DIR, "napari.yaml")) as f:
            manifest = yaml.safe_load(f)
        self.assertEqual(manifest["name"], "ivol")
        (command,) = manifest["contributions"]["commands"]
        (reader,) = manifest["contributions"]["readers"]
        self.assertEqual(reader["command"], command["id"])
        self.assertEqual(reader["filename_patterns"], ["*.ivol"])
        module, name = command["python_name"].split(":")
        self.assertIs(getattr(importlib.import_module(module), name), _napari.get_reader)

    def test_reader_gives_the_pyramid(self):
        with Volume() as v:
            self.assertIsNone(_napari.get_reader(v.path + ".tif"))
            self.assertIsNone(_napari.get_reader(os.path.join(v.tmp.name, "missing.ivol")))
            self.assertIsNone(_napari.get_reader([v.path, v.path]))
            read = _napari.get_reader([v.path])
            self.assertIsNotNone(read)
            ((data, options, kind),) = read(v.path)
            self.assertEqual(kind, "image")
            self.assertTrue(options["multiscale"])
            self.assertEqual(options["scale"], (0.5, 0.25, 0.125))
            self.assertEqual(options["translate"], (3.0, 2.0, 1.0))
            self.assertEqual(options["name"], "part")
            f = ivol.open(v.path)
            self.assertEqual(len(data), f.levels)
            for k, level in enumerate(data):
                with self.subTest(level=k):
                    want_shape = tuple(-(-n // (1 << k)) for n in v.array.shape)
                    self.assertEqual(level.shape, want_shape)
                    self.assertEqual(level.ndim, 3)
                    self.assertEqual(level.dtype, np.float32)
                    if k <= 4:  # 32 / 2^4 = 2: the dims are multiples of 2^k
                        got = np.asarray(level).astype(np.float64)
                        # Averages are stored as float32: a rounding per level.
                        np.testing.assert_allclose(got, block_means(v.array, k), rtol=0, atol=1e-5)
                        # A view napari takes of a level: a 2-D slice.
                        np.testing.assert_array_equal(level[1], got[1].astype(np.float32))


class Viewer(unittest.TestCase):
    def test_napari_viewer_opens_it(self):
        import napari
        import npe2

        manager = npe2.PluginManager.instance()
        if "ivol" not in manager._manifests:
            # Installed with pip the entry point registers it; from the build
            # folder (PYTHONPATH) the manifest is registered by hand.
            manager.register(npe2.PluginManifest.from_file(os.path.join(PACKAGE_DIR, "napari.yaml")))
        with Volume() as v:
            # napari's viewer model: its open(), reader dispatch and Image
            # layer, without the Qt window, whose canvas needs OpenGL (none
            # under QT_QPA_PLATFORM=offscreen here: napari.Viewer(show=False)
            # fails in vispy's glGetParameter).
            viewer = napari.components.ViewerModel()
            layers = viewer.open(v.path, plugin="ivol")
            self.assertEqual(len(layers), 1)
            layer = layers[0]
            self.assertIsInstance(layer, napari.layers.Image)
            self.assertTrue(layer.multiscale)
            f = ivol.open(v.path)
            self.assertEqual([tuple(d.shape) for d in layer.data], [f.level(k).shape for k in range(f.levels)])
            np.testing.assert_allclose(layer.scale, (0.5, 0.25, 0.125))
            np.testing.assert_allclose(layer.translate, (3, 2, 1))
            # What napari shows of plane z = 3 at full resolution: the layer's
            # slice, through its own slicing code.
            viewer.dims.ndisplay = 2
            viewer.dims.set_point(0, 3 * 0.5 + 3)
            layer.refresh()
            shown = np.asarray(layer._slice.image.raw)
            self.assertEqual(shown.ndim, 2)
            level = layer.data_level
            np.testing.assert_array_equal(shown, np.asarray(layer.data[level][3 >> level]))
            # The contrast spans the values (napari's own guess for a
            # multiscale image is the one-voxel coarsest level's).
            low, high = layer.contrast_limits
            self.assertLess(low, -2.0)
            self.assertGreater(high, 2.0)

    @unittest.skipUnless(os.environ.get("DISPLAY"), "no display: run under xvfb-run for the Qt canvas")
    def test_qt_canvas_shows_the_slice(self):
        import napari
        from qtpy.QtWidgets import QApplication

        with Volume() as v:
            viewer = napari.Viewer(show=True)
            try:
                viewer.open(v.path, plugin="ivol")
                for _ in range(20):
                    QApplication.processEvents()
                picture = viewer.screenshot(canvas_only=True, flash=False)[..., :3]
                # Noise of unit variance, shown with the limits above: many
                # grey levels, not the one colour of a blank canvas.
                self.assertGreater(len(np.unique(picture)), 50)
            finally:
                viewer.close()


if __name__ == "__main__":
    # One class per ctest: Viewer needs napari, Reader does not.
    unittest.main(argv=[__file__, "Viewer" if WITH_NAPARI else "Reader"], verbosity=2)
