"""The mocapedit command line: one module per sub-command under cli.commands.

May import: every layer but data; never pxr directly.
"""
