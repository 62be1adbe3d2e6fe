"""Front-end tools around a solve: previews, stationary and contact tags for review, measures of
stages (foot skate, plausibility).

May import: every layer but cli and data, and pxr.
"""
