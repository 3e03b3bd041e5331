"""PNG files that hold the same pixels in other bytes, as another zlib build would write them."""

from __future__ import annotations

import struct
import zlib


def recompressed(data: bytes, level: int = 1) -> bytes:
    """The PNG `data` with its pixel stream compressed again at zlib `level`: the same
    picture, other bytes (what a machine with another zlib makes of the same pixels)."""
    signature, pos = data[:8], 8
    chunks: list[tuple[bytes, bytes]] = []
    while pos < len(data):
        (length,) = struct.unpack_from(">I", data, pos)
        chunks.append((data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]))
        pos += 12 + length
    pixels = zlib.decompress(b"".join(body for kind, body in chunks if kind == b"IDAT"))
    out, written = [signature], False
    for kind, body in chunks:
        if kind == b"IDAT":
            if written:
                continue  # the whole stream went into the first IDAT
            body, written = zlib.compress(pixels, level), True
        crc = zlib.crc32(kind + body)
        out.append(struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc))
    return b"".join(out)
