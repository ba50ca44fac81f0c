"""Importers: real mocap formats -> :class:`solver.capture.Capture`."""
