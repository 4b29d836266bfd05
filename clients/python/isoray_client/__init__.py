"""A thin client of the isoray REST API (``/api/v1``): create a scene, push time steps as
NumPy arrays (sent as ``.npy``), render images into NumPy arrays, delete the scene.

    import numpy as np, isoray_client as iso
    scene = iso.Scene.create("http://127.0.0.1:8080", kind="metaballs", name="particles")
    scene.push(0, positions.astype(np.float32), time=0.0)
    image = scene.render(width=320, height=240)   # (240, 320, 3) uint8
    scene.delete()

Errors of the server come back as :class:`IsorayError` with the server's code, message and
the field it names.
"""
from .client import IsorayError, Scene
from .png import decode_png

__all__ = ["IsorayError", "Scene", "decode_png"]
