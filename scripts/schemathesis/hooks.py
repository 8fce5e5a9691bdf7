"""Schemathesis hooks for `openapi.yaml` (loaded by tests/schemathesis.rs with
SCHEMATHESIS_HOOKS=hooks from this folder): strategies for the two string formats JSON Schema
cannot describe, so positive tests send what the server really accepts.

- `png-base64`: a real PNG, base64-encoded (the `image` of a vectorize job);
- `svg`: a small well-formed SVG document (the `svg` a job starts from).
"""

import base64
import struct
import zlib

import schemathesis
from hypothesis import strategies as st


def _png(width, height, rgb):
    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)

    row = b"\x00" + bytes(rgb) * width
    raw = row * height
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


PNGS = [base64.b64encode(_png(w, h, c)).decode() for w, h, c in
        [(8, 8, (255, 0, 0)), (16, 12, (0, 128, 255)), (24, 24, (20, 200, 40)), (32, 16, (250, 250, 250))]]

SVGS = [
    '<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32" viewBox="0 0 32 32">'
    '<path d="M4 4L28 4L16 28Z" fill="#e33"/></svg>',
    '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 64 64">'
    '<circle cx="32" cy="32" r="20" fill="#36c"/><rect x="8" y="40" width="48" height="12" fill="#fc3"/></svg>',
]

schemathesis.openapi.format("png-base64", st.sampled_from(PNGS))
schemathesis.openapi.format("svg", st.sampled_from(SVGS))
