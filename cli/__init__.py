"""The ``rbstab`` command line: a thin click layer over :mod:`rbstab` (no physics here)."""
