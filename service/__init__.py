"""The user-facing layer: command line (``motionx``) and, later, the HTTP service."""
