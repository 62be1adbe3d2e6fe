"""The solve of a shot: the processor, its context and ordered passes, the guides, and batches of
shots on Dask.

May import: model, geometry, solve, inspect, usd; never pxr directly (usd/ does).
"""
