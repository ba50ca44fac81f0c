"""The glTF reader's error and the format's tables: GLB chunk types, accessor component types
and element sizes."""

from __future__ import annotations

from typing import Any

import numpy as np

from solver.errors import InputError

GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_CTYPE: dict[int, np.dtype[Any]] = {5120: np.dtype("i1"), 5121: np.dtype("u1"), 5122: np.dtype("<i2"),
                                    5123: np.dtype("<u2"), 5125: np.dtype("<u4"), 5126: np.dtype("<f4")}


class GltfError(InputError):
    """A glTF file is unreadable, or not a skinned, animated character; the message says why."""
