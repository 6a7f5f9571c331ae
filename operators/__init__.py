"""Operators: one module per user action (a ``bpy.types.Operator`` each).

Planned: import cameras, add photos, light, reconstruct, bake, select (KL
renders), export. Each module defines its operator classes, named like
``BRDF_OT_reconstruct`` with ``bl_idname = "brdf.reconstruct"``, and a
``CLASSES`` tuple; this package concatenates those tuples here, and
``brdf_addon`` registers them. Operators call ``core`` for the science.
"""

CLASSES = ()
