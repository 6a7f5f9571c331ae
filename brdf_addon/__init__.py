"""Blender-facing glue that is not an operator: properties, panels, registration.

Each UI module holds a ``CLASSES`` tuple; ``register()`` concatenates them in
dependency order (property groups before the panels and operators that use
them) and registers them with ``bpy.utils.register_classes_factory``.
"""

import bpy

from .. import operators
from . import panel, prefs, props

CLASSES = prefs.CLASSES + props.CLASSES + operators.CLASSES + panel.CLASSES

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(CLASSES)


def register() -> None:
    _register_classes()
    props.attach()


def unregister() -> None:
    props.detach()
    _unregister_classes()
