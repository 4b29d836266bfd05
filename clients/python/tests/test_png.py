"""The PNG decoder against PNGs this test writes itself, one per filter type (the reference
filters are written here from the PNG specification, sharing no code with the decoder)."""
import struct
import unittest
import zlib

import numpy as np

from isoray_client import decode_png


def chunk(kind, body):
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def encode(image, filters):
    """PNG bytes of ``image`` (h, w, 3) uint8, row y filtered with ``filters[y % len]``."""
    h, w, bpp = image.shape
    rows = []
    prev = [0] * (w * bpp)
    for y in range(h):
        line = [int(v) for v in image[y].reshape(-1)]
        f = filters[y % len(filters)]
        out = []
        for i, x in enumerate(line):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            pred = [0, a, b, (a + b) // 2, paeth(a, b, c)][f]
            out.append((x - pred) % 256)
        rows.append(bytes([f] + out))
        prev = line
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
            + chunk(b"IDAT", zlib.compress(b"".join(rows))) + chunk(b"IEND", b""))


class DecodePng(unittest.TestCase):
    def test_every_filter_type_round_trips(self):
        rng = np.random.default_rng(7)
        image = rng.integers(0, 256, (9, 11, 3), dtype=np.uint8)
        for filters in ([0], [1], [2], [3], [4], [0, 1, 2, 3, 4]):
            with self.subTest(filters=filters):
                np.testing.assert_array_equal(decode_png(encode(image, filters)), image)

    def test_rejects_what_is_not_a_png(self):
        with self.assertRaises(ValueError):
            decode_png(b"GIF89a....")


if __name__ == "__main__":
    unittest.main()
