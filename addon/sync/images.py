"""Blender images as numpy arrays."""
import numpy as np


def image_rgb(image):
    """(pixels, stored_as_srgb): float32 (H, W, 3) with row 0 at the top, and whether the
    values are sRGB-encoded (8-bit sRGB images) rather than linear; None if the image has no
    pixels (a missing file)."""
    width, height = image.size
    channels = image.channels
    if width == 0 or height == 0 or channels == 0:
        return None
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    pixels = pixels.reshape(height, width, channels)[::-1]  # Blender stores rows bottom-up
    pixels = pixels[..., :3] if channels >= 3 else np.repeat(pixels[..., :1], 3, axis=2)  # grey
    return np.ascontiguousarray(pixels), not image.is_float and image.colorspace_settings.name == "sRGB"


def srgb_to_linear(x):
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)

