"""Blender glue that is not an operator: properties, preferences, the panel, and the
library the operators and the batch entry share (light sources, COLMAP import,
photo list, G-buffers, the run, the material, the job file).

``CLASSES`` holds this package's classes in dependency order (preferences and
property groups first, then the panel); the extension's root ``__init__.py``
registers them together with ``operators.CLASSES``. Nothing here imports
``operators``: an operator calls into this package, never the other way.
"""

from . import panel, prefs, props

CLASSES = prefs.CLASSES + props.CLASSES + panel.CLASSES
