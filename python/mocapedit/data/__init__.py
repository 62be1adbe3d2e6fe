"""Demo data like skimage.data: the procedural walker, gestures and example stages. Library code
never imports it.

May import: model, geometry, solve, usd, formats and pxr.
"""
