"""The only library layer that touches USD: the schema API, the stage reader, the edits-layer
writer and format, Sdf helpers, the clip-layer layout, output files, UsdSkel evaluation.

May import: model, geometry, formats and pxr; no linear algebra.
"""
