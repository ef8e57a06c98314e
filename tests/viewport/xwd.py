"""Reads `xwd -root` screenshots (X Window Dump, 24/32-bit TrueColor) into numpy RGB."""
import struct

import numpy as np

_FIELDS = ("header_size file_version pixmap_format pixmap_depth width height xoffset byte_order "
           "bitmap_unit bitmap_bit_order bitmap_pad bits_per_pixel bytes_per_line visual_class "
           "red_mask green_mask blue_mask bits_per_rgb colormap_entries ncolors").split()


def read_xwd(path):
    """uint8 (H, W, 3), row 0 at the top."""
    with open(path, "rb") as f:
        raw = f.read()
    header = dict(zip(_FIELDS, struct.unpack(">20I", raw[:80])))
    if header["file_version"] != 7 or header["bits_per_pixel"] != 32:
        raise ValueError(f"{path}: unsupported xwd ({header['file_version']=}, {header['bits_per_pixel']=})")
    offset = header["header_size"] + 12 * header["ncolors"]
    w, h, stride = header["width"], header["height"], header["bytes_per_line"]
    pixels = np.frombuffer(raw, np.uint8, count=h * stride, offset=offset).reshape(h, stride)[:, :4 * w]
    words = pixels.view("<u4" if header["byte_order"] == 0 else ">u4").reshape(h, w).astype(np.uint32)
    channels = []
    for mask in (header["red_mask"], header["green_mask"], header["blue_mask"]):
        shift = (mask & -mask).bit_length() - 1
        channels.append(((words & mask) >> shift).astype(np.uint8))
    return np.stack(channels, axis=-1)
