"""MuJoCo as an independent oracle: inverse dynamics of our characters with ``mj_inverse``.

External wrenches (world frame, moment about the world origin; force) are applied to a
segment through ``mj_applyFT``; the joint forces we compare with are those the joints
must supply *in addition*: tau = qfrc_inverse - J^T f_ext. The root wrench is rebuilt from
MuJoCo's six root generalized forces: the three slides give the force, the three hinges
the moment about the root joint anchor (a 3x3 solve on their world axes).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from mjcf.builder import compile_model
from solver.character import Character
from solver.dynamics import DEFAULT_GRAVITY


@dataclass
class MujocoReplay:
    """A compiled model plus the index maps between our coordinates and MuJoCo's."""

    character: Character
    model: mujoco.MjModel
    data: mujoco.MjData
    qpos_index: np.ndarray  # our coordinate i -> MuJoCo qpos address
    dof_index: np.ndarray  # our coordinate i -> MuJoCo dof address
    root_joint_ids: np.ndarray

    @staticmethod
    def create(character: Character, gravity: Sequence[float] = DEFAULT_GRAVITY) -> MujocoReplay:
        model = compile_model(character, gravity)
        # inverse dynamics of the free motion only: no contact, limit or passive forces
        model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
        model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        data = mujoco.MjData(model)
        ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, nm) for nm in character.coordinate_names]
        if min(ids) < 0:
            raise RuntimeError("generated model lacks a coordinate joint")
        qpos = np.array([model.jnt_qposadr[i] for i in ids])
        dof = np.array([model.jnt_dofadr[i] for i in ids])
        root = np.array(ids[:6])
        return MujocoReplay(character, model, data, qpos, dof, root)

    def set_gravity(self, gravity: Sequence[float]) -> None:
        self.model.opt.gravity[:] = np.asarray(gravity, dtype=float)

    def inverse(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        qdd: np.ndarray,
        fext: Mapping[str, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Joint forces (n, T) and root wrench (6, T) for frames given as columns.

        ``fext`` maps a segment name to world wrenches (6, T): (moment about origin; force).
        """
        q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float).T).T for x in (q, qd, qdd))
        n, T = q.shape
        m, d = self.model, self.data
        tau = np.empty((n, T))
        h0 = np.empty((6, T))
        qfrc = np.zeros(m.nv)
        body_ids = {}
        for seg in fext or {}:
            bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, seg)
            if bid < 0:
                raise ValueError(f"unknown segment {seg!r}")
            body_ids[seg] = bid
        zero = np.zeros(3)
        for t in range(T):
            d.qpos[self.qpos_index] = q[:, t]
            d.qvel[self.dof_index] = qd[:, t]
            d.qacc[self.dof_index] = qdd[:, t]
            mujoco.mj_inverse(m, d)
            gen = d.qfrc_inverse.copy()
            if fext:
                qfrc[:] = 0.0
                for seg, w in fext.items():
                    w = np.asarray(w, dtype=float).reshape(6, -1)
                    wt = w[:, t if w.shape[1] > 1 else 0]
                    mujoco.mj_applyFT(m, d, wt[3:].copy(), wt[:3].copy(), zero, body_ids[seg], qfrc)
                gen -= qfrc
            tau[:, t] = gen[self.dof_index]
            # root wrench from the root's generalized forces
            force = tau[:3, t]
            axes = np.array([d.xaxis[j] for j in self.root_joint_ids[3:6]])
            anchor = d.xanchor[self.root_joint_ids[3]].copy()
            moment_at_anchor = np.linalg.solve(axes, tau[3:6, t])
            h0[:3, t] = moment_at_anchor + np.cross(anchor, force)
            h0[3:, t] = force
        return tau, h0


def total_mass(model: mujoco.MjModel) -> float:
    return float(mujoco.mj_getTotalmass(model))
