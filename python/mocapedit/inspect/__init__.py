"""Measures of edited motion: plausibility and quality metrics, overlaps, where every agent is over
the shot.

May import: model, geometry, solve; never pxr (usd/ evaluates stages into arrays for it).
"""
