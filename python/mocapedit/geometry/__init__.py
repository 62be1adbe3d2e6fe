"""Ground frames, rigid-transform math, trajectories, curves, clip sampling, and what a clip's
motion says about itself (stationary ranges, foot contacts).

May import: model and the compiled _solver; never pxr.
"""
