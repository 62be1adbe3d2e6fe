"""Motion-capture file formats read into plain arrays: BVH.

May import: model, geometry; never pxr.
"""
