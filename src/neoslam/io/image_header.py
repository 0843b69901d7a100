"""An encoded image's size read from its header, before it is decoded: a PNG of a megabyte can hold 32000 x 32000
pixels, and decoding it takes gigabytes before anything can check its size. PNG and JPEG (what cameras, KITTI and
ROS's CompressedImage carry); other formats give None and are decoded as they are."""

from __future__ import annotations

__all__ = ["MAX_IMAGE_PIXELS", "image_size", "oversized"]

MAX_IMAGE_PIXELS = 2**27  # 134 megapixels: far beyond a stereo camera's frame, far below a decompression bomb's
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_JPEG_SOI = b"\xff\xd8"
# JPEG start-of-frame markers (C0-CF but C4 DHT, C8 JPG, CC DAC): they carry the frame's height and width
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
_JPEG_SCAN_BYTES = 1 << 20  # the frame header comes before the image data; a file that hides it further is no image


def image_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG's IHDR or a JPEG's start-of-frame header; None when neither is found."""
    if data.startswith(_PNG_SIGNATURE) and len(data) >= 24 and data[12:16] == b"IHDR":
        return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if data.startswith(_JPEG_SOI):
        return _jpeg_size(data)
    return None


def _jpeg_size(data: bytes) -> tuple[int, int] | None:
    at = 2
    end = min(len(data), _JPEG_SCAN_BYTES)
    while at + 9 <= end:
        if data[at] != 0xFF:
            return None
        marker = data[at + 1]
        if marker == 0xFF:  # fill bytes before a marker
            at += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # markers without a length
            at += 2
            continue
        length = int.from_bytes(data[at + 2 : at + 4], "big")
        if marker in _SOF:
            return int.from_bytes(data[at + 7 : at + 9], "big"), int.from_bytes(data[at + 5 : at + 7], "big")
        if marker == 0xDA or length < 2:  # the scan starts: no frame header came before it
            return None
        at += 2 + length
    return None


def oversized(data: bytes) -> str | None:
    """Why an encoded image is too large to decode (its header's size over MAX_IMAGE_PIXELS), or None."""
    size = image_size(data)
    if size is None:
        return None
    width, height = size
    if width * height > MAX_IMAGE_PIXELS:
        return (
            f"{width}x{height} pixels in its header, more than the {MAX_IMAGE_PIXELS // 2**20} megapixels an image "
            "may have (refused before decoding)"
        )
    return None
