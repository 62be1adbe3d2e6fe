"""Ground frames, rigid-transform math, trajectories and their shape, curves, clip sampling, and
what a clip's motion says about itself (stationary ranges, foot contacts).

May import: model and the compiled _solver; never pxr.
"""
