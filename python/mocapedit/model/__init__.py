"""Plain data shared by every layer: agents, clips, stage facts (numpy, no USD), errors, limits,
progress, report entries, names (identifiers, joints found by name).

May import: numpy only; nothing else of mocapedit.
"""
