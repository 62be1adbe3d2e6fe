"""One module per ``mocapedit`` sub-command; each defines ``register(subparsers)``."""
