"""Writing test images with OpenImageIO (no bpy): pixels as given, and metadata.

``write_image(path, pixels, fmt, attributes)``: (H, W, C) pixels in the file's
pixel type ``fmt`` (``oiio.UINT8``, ``oiio.FLOAT``, ...); attributes are
(name, value) pairs or a dict: str, int and float values as they are, tuples
of floats (GPS degrees, minutes, seconds) as ``float[n]``.
"""

import numpy as np
import OpenImageIO as oiio


def write_image(path, pixels, fmt, attributes=()):
    """Write (H, W, C) ``pixels`` to ``path`` as pixel type ``fmt``; returns ``path``."""
    pixels = np.ascontiguousarray(pixels)
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    pairs = attributes.items() if isinstance(attributes, dict) else attributes
    for name, value in pairs:
        if isinstance(value, tuple):
            spec.attribute(name, oiio.TypeDesc(f"float[{len(value)}]"), value)
        else:
            spec.attribute(name, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), oiio.geterror()
    assert out.write_image(pixels)
    out.close()
    return path
