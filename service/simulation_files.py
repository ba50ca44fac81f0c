"""The files a simulation writes and their media types (``service.simulation`` writes them,
``service.store`` stores them, the routes list them): one list, imported by each."""

from __future__ import annotations

#: the files of a simulation and their media types, in the order the API lists them
FILES: dict[str, str] = {
    "report.json": "application/json",
    "model.xml": "application/xml",
    "rollout.npz": "application/octet-stream",
    "simulated.glb": "model/gltf-binary",
    "simulation.png": "image/png",
}
