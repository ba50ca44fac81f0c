"""IPOPT iteration callback that stops a solve when asked (cancel, time limit): returning 1
makes IPOPT end with ``User_Requested_Stop``."""

from __future__ import annotations

from typing import Any

import casadi as ca


class StopFlag:
    check: Any = None


STOP = StopFlag()


class _Stop(ca.Callback):
    """IPOPT iteration callback: returning 1 stops the solve (User_Requested_Stop)."""

    def __init__(self, name: str, nx: int, ng: int) -> None:
        ca.Callback.__init__(self)
        self.nx, self.ng = nx, ng
        self.construct(name, {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        name = ca.nlpsol_out(i)
        if name == "f":
            return ca.Sparsity.scalar()
        if name in ("x", "lam_x"):
            return ca.Sparsity.dense(self.nx)
        if name in ("g", "lam_g"):
            return ca.Sparsity.dense(self.ng)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        check = STOP.check
        return [1 if check is not None and check() else 0]


class StopCallbacks:
    def __init__(self) -> None:
        self._made: dict[tuple[int, int], _Stop] = {}

    def get(self, nx: int, ng: int) -> _Stop:
        key = (nx, ng)
        if key not in self._made:  # kept alive: IPOPT holds a reference to the callback
            self._made[key] = _Stop(f"stop_{nx}_{ng}", nx, ng)
        return self._made[key]


STOP_CALLBACK = StopCallbacks()
