"""EXR and PNG helpers: passes under their Blender names (PASSES labels), PNG without Pillow."""
from __future__ import annotations

import struct
import zlib

import numpy as np

def layer_channels(name, channels):
    """EXR channel names for a pass of parallax_core.PASSES, by its label and channel ids:
    ("combined", 4) -> ["Combined.R", ..., "Combined.A"]. Raises ValueError for a name that
    is no pass or a channel count that is not the pass'."""
    from . import PASSES

    row = next((p for p in PASSES if p.name == name), None)
    if row is None:
        raise ValueError(f"EXR: unknown pass '{name}' (passes: {', '.join(p.name for p in PASSES)})")
    if channels != row.channels:
        raise ValueError(f"EXR pass '{name}': {channels} channels, the pass has {row.channels}")
    return [f"{row.label}.{c}" for c in row.channel_ids]


def write_exr(path, layers):
    """Write passes {name: (H,W,C) or (H,W) array} to one single-part float32 ZIP EXR.
    Row 0 of each array is the top of the image."""
    import OpenEXR

    channels, size = {}, None
    for name, a in layers.items():
        a = np.asarray(a, dtype=np.float32)
        if a.ndim == 2:
            a = a[:, :, None]
        if a.ndim != 3:
            raise ValueError(f"EXR pass '{name}': shape {a.shape}, expected (H,W,C)")
        if size is None:
            size = a.shape[:2]
        elif a.shape[:2] != size:
            raise ValueError(f"EXR pass '{name}': size {a.shape[:2]} differs from {size}")
        for c, ch in enumerate(layer_channels(name, a.shape[2])):
            channels[ch] = np.ascontiguousarray(a[:, :, c])
    if not channels:
        raise ValueError("EXR: no passes to write")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, channels).write(str(path))


def read_exr(path):
    """Read every channel of every part: {channel name: (H,W) array}. Channels of later
    parts whose name is already taken get the part name as a prefix."""
    import OpenEXR

    out = {}
    with OpenEXR.File(str(path), separate_channels=True) as f:
        for part in f.parts:
            for name, ch in part.channels.items():
                key = name if name not in out else f"{part.name()}.{name}"
                out[key] = np.array(ch.pixels)
    return out


def srgb_encode(linear):
    """Linear -> sRGB transfer function (IEC 61966-2-1), input clipped to [0,1]."""
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float64)), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def write_png(path, rgb):
    """Write a linear (H,W,3|4) or (H,W) image as an 8-bit sRGB PNG (alpha dropped)."""
    a = np.asarray(rgb)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] < 3:
        raise ValueError(f"PNG: shape {a.shape}, expected (H,W,3)")
    px = np.round(srgb_encode(a[:, :, :3]) * 255.0).astype(np.uint8)
    h, w = px.shape[:2]
    raw = np.concatenate([np.zeros((h, 1), np.uint8), px.reshape(h, w * 3)], axis=1)

    def chunk(tag, data):
        body = tag + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    png = (b"\x89PNG\r\n\x1a\n"
           + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw.tobytes(), 6))
           + chunk(b"IEND", b""))
    with open(path, "wb") as f:
        f.write(png)
