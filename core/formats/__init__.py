"""File formats: each reader gives a file-faithful result, then one conversion to `Motion`."""

import zlib
from pathlib import Path

from ..errors import ParseError

#: text motion files (BVH, AMC, ASF, CSV) larger than this, on disk or unzipped, are refused:
#: a 10-minute take is about 100 MB, and a hostile .bvh.gz of a few kB can unzip to many GB
MAX_TEXT_BYTES = 512 << 20


def read_text_bytes(path):
    """The bytes of a text motion file, gunzipped when gzip-compressed, at most
    :data:`MAX_TEXT_BYTES`; :class:`ParseError` otherwise."""
    path = Path(path)
    try:
        on_disk = path.stat().st_size
        if on_disk > MAX_TEXT_BYTES:
            raise ParseError(f"file too large ({on_disk >> 20} MB; at most "
                             f"{MAX_TEXT_BYTES >> 20} MB)", path)
        raw = path.read_bytes()
    except OSError as exc:
        raise ParseError(f"cannot read file ({exc.strerror})", path) from None
    if raw[:2] != b"\x1f\x8b":
        return raw
    out = []
    size = 0  # unzipped so far
    while raw[:2] == b"\x1f\x8b":  # one gzip member after another
        unzip = zlib.decompressobj(16 + zlib.MAX_WBITS)
        try:
            part = unzip.decompress(raw, MAX_TEXT_BYTES + 1 - size)
        except zlib.error as exc:
            raise ParseError(f"corrupt gzip data ({exc})", path) from None
        size += len(part)
        if size > MAX_TEXT_BYTES:
            raise ParseError(f"unzips to over {MAX_TEXT_BYTES >> 20} MB", path)
        if not unzip.eof:
            raise ParseError("corrupt gzip data (the stream ends early)", path)
        out.append(part)
        raw = unzip.unused_data
    return b"".join(out)
