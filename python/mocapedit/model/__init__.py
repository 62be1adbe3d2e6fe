"""Plain data shared by every layer: agents, clips, stage facts (numpy, no USD), errors, limits,
progress, report entries.

May import: numpy only; nothing else of mocapedit.
"""
