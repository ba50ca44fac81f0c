"""Skinned glTF 2.0 importer: a character's skeleton and one walk animation (``.glb``, or ``.gltf``
with its buffers embedded).

Public API::

    read_gltf(path) -> GltfAsset                 # the document and its one binary buffer
    parse_gltf(data, where) -> GltfAsset         # the same from bytes (GLB or glTF JSON)
    gltf_track(path, *, mass=None, joints=None, animation=None, belt_speed=None) -> SkeletonTrack
    load_gltf(path, *, mass=None, lower_only=None, joints=None, animation=None, belt_speed=None) -> Capture

**What is read.** One animation: the first, or ``animation`` (its name, or its index). One
skin: the one whose joints that animation drives most (the first on a tie). The skeleton is
the tree of the skin's joints under their top joint (of several top joints, the one with the
most joints below it; nodes between two joints that are not joints of the skin are joints of
the rig too); the nodes above it (Mixamo's ``Armature``, scale 0.01 and a rotation) are folded
into the ground frame, so the rig lives in its root's parent space, with that space's units:
centimetres for a Mixamo character. Their transforms must be uniform scales, rotations and
translations; an animated node above the skeleton moves its root (its scale may not change).

**Sampling.** The animation's channels on the skeleton's nodes are sampled on a uniform clock
at the animation's own rate (the median interval between its keyframes), from its first to
its last keyframe, each with its sampler's interpolation: ``STEP``, ``LINEAR`` (slerp for
rotations, shortest way), ``CUBICSPLINE`` (cubic Hermite with the sampler's tangents,
rotations normalised); a node the animation does not drive keeps its own TRS. Joints may
carry a constant uniform scale (their children's offsets are scaled); an animated or
non-uniform joint scale is refused. A joint whose translation changes along the clip (a
pelvis under a ``root`` joint) keeps it as a position channel of the rig.

**Roles and landmarks** as the BVH importer's (:mod:`solver.io.roles`, :mod:`solver.io.joint_track`):
joint roles from the names (Mixamo, Unreal, Unity, Blender, …) and the hierarchy, or
``joints`` (role -> joint name); the rest pose is the nodes' own TRS. glTF is Y up and in
metres: the scene's up direction, carried into the skeleton's parent space, is our Z; our X
is the facing direction (perpendicular to the hip line, averaged over the clip; glTF
characters face +Z); the floor is the 2nd percentile of the sole points' heights. A
character whose legs are not 0.45-1.2 m long in the scene is refused. glTF has no subject
mass: pass ``mass`` (kg).

**The rig** (``capture.rig``, format ``"gltf"``): the skeleton's joints, their rest offsets
(parent-space units, joint scales applied), the sampled local rotations and root
translation, and in ``extra`` what the writer (``solver.export.rig_gltf``) needs: the joints'
node indices, the skin, the joints' accumulated scales, and the source asset itself (a GLB,
base64) without its animations and with every buffer and embedded image in its one binary
chunk. Files over :data:`MAX_BYTES` are refused.

The package, one module per job: ``base`` (the error, the format's tables), ``container`` (GLB
and glTF JSON in, buffers merged; a GLB out, an asset without its animations), ``references``
(every index and byte range of a document checked), ``nodes`` (the node hierarchy and
transforms), ``animation`` (picking and sampling the clip), ``skeleton`` (the skin's joints and
their animation in the skeleton's parent space), ``trial`` (landmarks, roles, the capture and
its rig: the reader functions).
"""

from solver.io.gltf.base import GltfError
from solver.io.gltf.container import MAX_BYTES, GltfAsset, parse_gltf, read_gltf
from solver.io.gltf.trial import gltf_track, load_gltf, trial_files

__all__ = ["MAX_BYTES", "GltfAsset", "GltfError", "gltf_track", "load_gltf", "parse_gltf", "read_gltf", "trial_files"]
