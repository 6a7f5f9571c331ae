"""Tabulated BRDFs: MERL tables, analytic models, the database, the PCA basis, shading, metrics."""
