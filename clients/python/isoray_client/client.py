"""The HTTP calls: one :class:`Scene` per scene on a server, with its write token."""
from __future__ import annotations

import io
from typing import Any, Optional, Sequence

import numpy as np
import requests

from .png import decode_png

NPY = "application/x-npy"


class IsorayError(Exception):
    """An answer other than success: the HTTP status and the server's error body."""

    def __init__(self, status: int, code: str, message: str, field: Optional[str] = None):
        super().__init__(f"{status} {code}: {message}" + (f" (field {field})" if field else ""))
        self.status = status
        self.code = code
        self.message = message
        self.field = field


def _check(response: requests.Response) -> requests.Response:
    if response.ok:
        return response
    try:
        body = response.json()
        code, message, field = body.get("code", ""), body.get("message", ""), body.get("field")
    except ValueError:
        code, message, field = "", response.text, None
    raise IsorayError(response.status_code, code, message, field)


def to_npy(array: np.ndarray) -> bytes:
    """The ``.npy`` bytes of ``array`` (little-endian float32, C order), as the server reads them."""
    a = np.ascontiguousarray(array, dtype="<f4")
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


class Scene:
    """A stored scene on an isoray server. Make one with :meth:`Scene.create` (which keeps
    the write token) or attach to an existing id with ``Scene(server, id, token)``."""

    def __init__(self, server: str, id: str, write_token: Optional[str] = None,
                 *, session: Optional[requests.Session] = None, timeout: float = 120.0):
        self.server = server.rstrip("/")
        self.id = id
        self.write_token = write_token
        self.timeout = timeout
        self._http = session or requests.Session()

    @property
    def url(self) -> str:
        """The scene's API address."""
        return f"{self.server}/api/v1/scenes/{self.id}"

    @property
    def viewer_url(self) -> str:
        """The browser viewer's address for this scene."""
        return f"{self.server}/?scene={self.id}"

    @classmethod
    def create(cls, server: str, kind: str = "metaballs", name: str = "scene", *,
               admin_token: Optional[str] = None, session: Optional[requests.Session] = None,
               **spec: Any) -> "Scene":
        """Creates a scene (``POST /api/v1/scenes``). ``spec`` holds the rest of the scene
        description (``description``, ``metaballs``, ``camera``, ``isovalue``, ``lighting``...)."""
        http = session or requests.Session()
        body = {"kind": kind, "name": name, **spec}
        headers = {"Authorization": f"Bearer {admin_token}"} if admin_token else {}
        r = _check(http.post(f"{server.rstrip('/')}/api/v1/scenes", json=body, headers=headers,
                             timeout=120))
        created = r.json()
        return cls(server, created["scene"]["id"], created["write_token"], session=http)

    def _auth(self) -> dict:
        if not self.write_token:
            raise ValueError("this scene has no write token: create it, or pass the token")
        return {"Authorization": f"Bearer {self.write_token}"}

    def info(self) -> dict:
        """The scene's description (``GET /api/v1/scenes/{id}``)."""
        return _check(self._http.get(self.url, timeout=self.timeout)).json()

    def steps(self) -> list:
        """The stored steps (index, time, primitives, columns...)."""
        return _check(self._http.get(f"{self.url}/steps", timeout=self.timeout)).json()["steps"]

    def push(self, step: int, array: np.ndarray, time: Optional[float] = None) -> dict:
        """Stores ``array`` (one row per primitive: ``x y z`` and the kind's further columns)
        as step ``step`` at ``time`` seconds (default: the step index). Sent as ``.npy``."""
        if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 0:
            raise ValueError(f"step must be a non-negative integer, not {step!r}")
        a = np.asarray(array)
        if a.ndim not in (1, 2):
            raise ValueError(f"array must have one row per primitive (2-D), not shape {a.shape}")
        params = {} if time is None else {"time": repr(float(time))}
        headers = {"Content-Type": NPY, **self._auth()}
        r = _check(self._http.put(f"{self.url}/steps/{int(step)}", params=params,
                                  data=to_npy(a), headers=headers, timeout=self.timeout))
        return r.json() if r.content else {}

    def render(self, width: int = 640, height: int = 480, *, step: Optional[int] = None,
               time: Optional[float] = None, camera: Optional[dict] = None,
               isovalue: Optional[float] = None, effects: Optional[dict] = None) -> np.ndarray:
        """One image of the scene (``POST .../render``, lossless PNG) as a ``(height, width, 3)``
        ``uint8`` array. ``camera`` is ``{"eye": [...], "target": [...], "up": [...],
        "fov_y_deg": ...}``; ``effects`` as in the websocket's ``effects`` message."""
        body: dict = {"width": int(width), "height": int(height), "format": "png"}
        for key, value in (("step", step), ("time", time), ("camera", camera),
                           ("isovalue", isovalue), ("effects", effects)):
            if value is not None:
                body[key] = value
        r = _check(self._http.post(f"{self.url}/render", json=body, timeout=self.timeout))
        return decode_png(r.content)

    def delete(self) -> None:
        """Deletes the scene and every stored step."""
        _check(self._http.delete(self.url, headers=self._auth(), timeout=self.timeout))

    def __repr__(self) -> str:
        return f"Scene({self.server!r}, {self.id!r})"
