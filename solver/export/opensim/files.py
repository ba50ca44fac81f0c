"""OpenSim's text files: storage (``.mot``, :func:`write_mot`), marker trajectories (``.trc``,
:func:`write_trc`), ExternalLoads (:func:`external_loads_xml`) and InverseDynamicsTool setups
(:func:`id_setup_xml`), and the model's own text (its gravity set, :func:`with_gravity`; 3.x
socket paths rewritten, :func:`repaired_model_text`)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from solver.export.opensim.base import ID_OUTPUT_FILE, LOWPASS_HZ, OpenSimExportError


def write_mot(path: str | Path, name: str, labels: Sequence[str], times: np.ndarray, data: np.ndarray, *,
              in_degrees: bool, digits: int = 8) -> None:
    """An OpenSim storage file (version 1 header, tab-separated, ``time`` first)."""
    data = np.asarray(data, dtype=float)
    lines = [name, "version=1", f"nRows={data.shape[0]}", f"nColumns={len(labels) + 1}",
             f"inDegrees={'yes' if in_degrees else 'no'}", "endheader", "\t".join(["time", *labels])]
    fmt = f"%.{digits}f"
    for k in range(data.shape[0]):
        lines.append("\t".join([fmt % times[k], *(fmt % v for v in data[k])]))
    Path(path).write_text("\n".join(lines) + "\n")


def write_trc(path: str | Path, names: Sequence[str], times: np.ndarray, xyz: np.ndarray, rate: float) -> None:
    """Marker trajectories (S, M, 3), metres, as a ``.trc`` (OpenSim's MarkersReference reads it)."""
    S, M = xyz.shape[:2]
    head = [f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"{rate:g}\t{rate:g}\t{S}\t{M}\tm\t{rate:g}\t1\t{S}",
            "\t".join(["Frame#", "Time", *(f"{n}\t\t" for n in names)]).rstrip("\t"),
            "\t".join(["", "", *(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(M))]), ""]
    rows = ["\t".join([str(k + 1), f"{times[k]:.8f}", *(f"{v:.8f}" for v in xyz[k].ravel())]) for k in range(S)]
    Path(path).write_text("\n".join(head + rows) + "\n")


def external_loads_xml(feet: Mapping[str, str], datafile: str,
                       columns: Sequence[tuple[str, str, str, str]] | None = None) -> str:
    """ExternalLoads for the two feet: by default columns ``ground_force_{r,l}_v/p`` and
    ``ground_torque_{r,l}_``; ``columns``: (side, force, point, torque) identifiers instead."""
    cols = columns or [(side, f"ground_force_{s}_v", f"ground_force_{s}_p", f"ground_torque_{s}_")
                       for side, s in (("right", "r"), ("left", "l"))]
    forces = []
    for k, (side, f_id, p_id, t_id) in enumerate(cols):
        forces.append(f"""			<ExternalForce name="{side}_foot_{k + 1}">
				<appliesForce>true</appliesForce>
				<applied_to_body>{feet[side]}</applied_to_body>
				<force_expressed_in_body>ground</force_expressed_in_body>
				<point_expressed_in_body>ground</point_expressed_in_body>
				<force_identifier>{f_id}</force_identifier>
				<point_identifier>{p_id}</point_identifier>
				<torque_identifier>{t_id}</torque_identifier>
			</ExternalForce>""")
    body = "\n".join(forces)
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
	<ExternalLoads name="externalloads">
		<objects>
{body}
		</objects>
		<groups />
		<datafile>{datafile}</datafile>
	</ExternalLoads>
</OpenSimDocument>
"""


def id_setup_xml(model: str, coordinates: str, external_loads: str, t0: float, t1: float, *,
                 lowpass: float | None = LOWPASS_HZ, output: str = ID_OUTPUT_FILE, results: str = ".") -> str:
    """An InverseDynamicsTool setup (muscles excluded, coordinates low-passed at ``lowpass`` Hz,
    or not filtered: None)."""
    lowpass = -1.0 if lowpass is None else float(lowpass)
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
	<InverseDynamicsTool name="inverse_dynamics">
		<results_directory>{results}</results_directory>
		<model_file>{model}</model_file>
		<time_range> {t0:.6f} {t1:.6f}</time_range>
		<forces_to_exclude> Muscles</forces_to_exclude>
		<external_loads_file>{external_loads}</external_loads_file>
		<coordinates_file>{coordinates}</coordinates_file>
		<lowpass_cutoff_frequency_for_coordinates>{lowpass:g}</lowpass_cutoff_frequency_for_coordinates>
		<output_gen_force_file>{output}</output_gen_force_file>
	</InverseDynamicsTool>
</OpenSimDocument>
"""


def with_gravity(text: bytes, gravity: np.ndarray) -> tuple[bytes, str | None]:
    """The model with its ``<gravity>`` set to ``gravity`` (OpenSim ground, m/s²) when it differs
    from the model's by more than 1e-6 m/s² (a motion in another gravity, e.g. a λ optimum on
    the gravity axis); returns the text and what was changed (None: unchanged)."""
    m = re.search(rb"<gravity>([^<]*)</gravity>", text)
    old = np.array([0.0, -9.80665, 0.0]) if m is None else np.array([float(v) for v in m.group(1).split()])
    g = np.asarray(gravity, dtype=float)
    if old.shape == (3,) and np.max(np.abs(old - g)) <= 1e-6:
        return text, None
    new = "<gravity>{:.9g} {:.9g} {:.9g}</gravity>".format(*g).encode()
    if m is None:
        raise OpenSimExportError("the motion's OpenSim model has no <gravity> element to set the motion's gravity in")
    changed = f"gravity {old.tolist()} -> {np.round(g, 6).tolist()} m/s² (the motion's environment)"
    return text[:m.start()] + new + text[m.end():], changed


def repaired_model_text(text: bytes) -> tuple[bytes, bool]:
    """A model whose socket paths name bodies as ``../body`` (3.x-era files that OpenSim 4
    cannot connect) with those paths rewritten to ``/bodyset/body`` (``/ground``); every other
    element kept (muscles, markers). Returns the text and whether anything changed."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise OpenSimExportError(f"the motion's OpenSim model is not valid XML ({e})") from None
    model = root.find("Model")
    if model is None:
        raise OpenSimExportError("the motion's OpenSim model has no <Model> element")
    bodies = {b.get("name") for b in model.iter("Body")}
    changed = False
    for el in model.iter():
        if el.tag.startswith("socket_") and el.text:
            m = re.fullmatch(r"(?:\.\./)+(\w+)", el.text.strip())
            if m and (m.group(1) == "ground" or m.group(1) in bodies):
                el.text = "/ground" if m.group(1) == "ground" else "/bodyset/" + m.group(1)
                changed = True
    if not changed:
        return text, False
    return b'<?xml version="1.0" encoding="UTF-8" ?>\n' + ET.tostring(root, encoding="utf-8"), True
