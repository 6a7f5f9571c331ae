"""Writing test images with OpenImageIO (no bpy): pixels as given, and metadata.

``write_image(path, pixels, fmt, attributes)``: (H, W, C) pixels in the file's
pixel type ``fmt`` (``oiio.UINT8``, ``oiio.FLOAT``, ...); attributes are
(name, value) pairs or a dict: str, int and float values as they are, tuples
of floats (GPS degrees, minutes, seconds) as ``float[n]``. ``origin`` and
``frame`` write an EXR whose data window (the pixels, top-left at origin x, y)
differs from its display window frame (x, y, width, height), as a render cropped
to a region or with overscan is written; ``names`` the channels' names (a
multilayer EXR's ``ViewLayer.Combined.R``, ...).
"""

import numpy as np
import OpenImageIO as oiio


def write_image(path, pixels, fmt, attributes=(), origin=None, frame=None, names=None):
    """Write (H, W, C) ``pixels`` to ``path`` as pixel type ``fmt``; returns ``path``."""
    pixels = np.ascontiguousarray(pixels)
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    if origin is not None:
        spec.x, spec.y = origin
    if frame is not None:
        spec.full_x, spec.full_y, spec.full_width, spec.full_height = frame
    if names is not None:
        spec.channelnames = names
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
