"""The bake: the lobe model Cycles renders exactly (lobes) and its fit to a table (fitting)."""
