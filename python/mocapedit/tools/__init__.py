"""Front-end tools around a solve: previews, stationary and contact tags for review.

May import: every layer but cli and data, and pxr.
"""
