"""The science, pure numpy/scipy, never bpy: brdf (tables and basis), capture (photos and
cameras), method (Ono et al. 2017, photo to table) and bake (table to Cycles lobes);
files writes every output through a temporary name."""
