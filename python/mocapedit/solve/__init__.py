"""One module per algorithm of the deliverable (path editing, time warp, collision avoidance,
layering, foot locking): problem builders and keyword-argument wrappers over _solver.

May import: model, geometry and _solver; never pxr.
"""
