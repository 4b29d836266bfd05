"""A small PNG decoder (8-bit greyscale, RGB or RGBA, not interlaced) into NumPy, so the
client needs nothing beyond NumPy and the standard library's zlib."""
from __future__ import annotations

import struct
import zlib

import numpy as np

SIGNATURE = b"\x89PNG\r\n\x1a\n"
CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}  # colour type -> samples per pixel


def _paeth_row(line: np.ndarray, prev: np.ndarray, bpp: int) -> np.ndarray:
    out = np.zeros(len(line), dtype=np.int32)
    x = line.astype(np.int32)
    b = prev.astype(np.int32)
    for i in range(len(line)):
        a = out[i - bpp] if i >= bpp else 0
        c = b[i - bpp] if i >= bpp else 0
        p = a + b[i] - c
        pa, pb, pc = abs(p - a), abs(p - b[i]), abs(p - c)
        pred = a if pa <= pb and pa <= pc else (b[i] if pb <= pc else c)
        out[i] = (x[i] + pred) & 0xFF
    return out.astype(np.uint8)


def _average_row(line: np.ndarray, prev: np.ndarray, bpp: int) -> np.ndarray:
    out = np.zeros(len(line), dtype=np.int32)
    for i in range(len(line)):
        a = out[i - bpp] if i >= bpp else 0
        out[i] = (int(line[i]) + ((a + int(prev[i])) >> 1)) & 0xFF
    return out.astype(np.uint8)


def _sub_row(line: np.ndarray, bpp: int) -> np.ndarray:
    # Each byte adds the reconstructed byte bpp before it: a running sum per channel, mod 256.
    pixels = line.reshape(-1, bpp).astype(np.uint32)
    return (np.cumsum(pixels, axis=0) & 0xFF).astype(np.uint8).reshape(-1)


def decode_png(data: bytes) -> np.ndarray:
    """The image in ``data`` as ``(height, width, channels)`` ``uint8`` (``(h, w)`` for grey)."""
    if data[:8] != SIGNATURE:
        raise ValueError("not a PNG image")
    pos, idat, header = 8, [], None
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        chunk = data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", chunk)
        elif kind == b"IDAT":
            idat.append(chunk)
        elif kind == b"IEND":
            break
    if header is None:
        raise ValueError("PNG without IHDR")
    width, height, depth, colour, _, _, interlace = header
    if depth != 8 or colour not in CHANNELS or interlace != 0:
        raise ValueError(f"unsupported PNG: bit depth {depth}, colour type {colour}, interlace {interlace}")
    bpp = CHANNELS[colour]
    stride = width * bpp
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8)
    if raw.size != height * (stride + 1):
        raise ValueError("PNG data has the wrong length")
    rows = raw.reshape(height, stride + 1)
    out = np.zeros((height, stride), dtype=np.uint8)
    prev = np.zeros(stride, dtype=np.uint8)
    for y in range(height):
        kind, line = rows[y, 0], rows[y, 1:]
        if kind == 0:
            cur = line.copy()
        elif kind == 1:
            cur = _sub_row(line, bpp)
        elif kind == 2:
            cur = line + prev  # uint8 wraps mod 256
        elif kind == 3:
            cur = _average_row(line, prev, bpp)
        elif kind == 4:
            cur = _paeth_row(line, prev, bpp)
        else:
            raise ValueError(f"unknown PNG filter {kind} in row {y}")
        out[y] = cur
        prev = cur
    image = out.reshape(height, width, bpp)
    return image[:, :, 0] if bpp == 1 else image
