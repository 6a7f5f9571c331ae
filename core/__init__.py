"""The science: pure numpy/scipy, never imports bpy (MERL tables, analytic models, the
PCA basis, optimal sampling, reconstruction, shading and metrics)."""
