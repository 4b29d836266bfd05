"""The client against a real isoray server, whose address is in ``ISORAY_URL`` (the Rust test
``tests/tests/api/python_client.rs`` starts one and runs these): create a scene, push steps
as ``.npy`` from NumPy arrays, render them into NumPy images, delete the scene."""
import os
import unittest

import numpy as np

import isoray_client as iso

SERVER = os.environ.get("ISORAY_URL")
CAMERA = {"eye": [0.0, 0.0, 6.0], "target": [0.0, 0.0, 0.0], "fov_y_deg": 45.0}


def blob(offset):
    """400 balls in a ball of radius 1 around ``(offset, 0, 0)``."""
    rng = np.random.default_rng(3)
    p = rng.normal(0.0, 1.0, (400, 3))
    p *= (rng.uniform(0, 1, (400, 1)) ** (1 / 3)) / np.linalg.norm(p, axis=1, keepdims=True)
    p[:, 0] += offset
    return p.astype(np.float32)


class AgainstServer(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        if not SERVER:
            raise RuntimeError("set ISORAY_URL to the address of a running isoray server")

    def setUp(self):
        self.scene = iso.Scene.create(SERVER, kind="metaballs", name="python client test",
                                      metaballs={"radius": 0.3, "strength": 1.0},
                                      camera=CAMERA, isovalue=0.5)

    def tearDown(self):
        try:
            self.scene.delete()
        except iso.IsorayError:
            pass

    def test_create_push_render_delete(self):
        s = self.scene
        self.assertEqual(s.info()["kind"], "metaballs")
        s.push(0, blob(-1.2), time=0.0)
        s.push(1, blob(1.2), time=0.5)
        steps = s.steps()
        self.assertEqual([(x["index"], x["time"], x["primitives"]) for x in steps],
                         [(0, 0.0, 400), (1, 0.5, 400)])

        left = s.render(96, 64, step=0)
        right = s.render(96, 64, step=1)
        self.assertEqual((left.shape, left.dtype), ((64, 96, 3), np.uint8))
        # The blob is lit on a dark background: the image is not flat, and the blob sits left
        # of the centre in step 0 and right of it in step 1 (the camera looks down -z, x right).
        grey = lambda img: img.astype(float).mean(axis=2)
        for img in (left, right):
            self.assertGreater(grey(img).std(), 10.0)
        bright = lambda img: (grey(img) > grey(img).mean()).nonzero()[1].mean()
        self.assertLess(bright(left), 48)
        self.assertGreater(bright(right), 48)
        # Same state, same view: the same bytes (the engine is deterministic).
        np.testing.assert_array_equal(s.render(96, 64, step=0), left)

        s.delete()
        with self.assertRaises(iso.IsorayError) as err:
            s.info()
        self.assertEqual(err.exception.status, 404)

    def test_bad_input_names_the_field(self):
        with self.assertRaises(iso.IsorayError) as err:
            self.scene.push(0, np.array([[0.0, 0.0, np.nan]], dtype=np.float32))
        self.assertEqual(err.exception.status, 400)
        with self.assertRaises(iso.IsorayError) as err:
            self.scene.render(0, 64)
        self.assertEqual(err.exception.status, 400)
        self.assertIn("width", err.exception.field or err.exception.message)


if __name__ == "__main__":
    unittest.main()
