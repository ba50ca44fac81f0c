"""Exact sparse derivatives of an NLP made of many calls of a few small generic functions.

Each kind of term (the equations of motion of one segment, the contact rows of one frame, a
cost of one frame, ...) is a small SX function; its Jacobian and the Hessian of its
Lagrangian are generated once, evaluated for every call with ``map`` and scattered into the
global sparse matrices by one constant sparse matrix. Build time stays linear in the number
of frames (a global symbolic Hessian is superlinear) with the same exact second derivatives.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sps

MAP_THREADS = 2  # heavy per-call derivative evaluations run on this many threads


def lagrangian_hessian(fn: ca.Function, n_var_inputs: int) -> ca.Function:
    """H(inputs..., lam) = triu(∇²_vars (lam · fn)), vars = the first ``n_var_inputs`` inputs."""
    ins = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
    out = fn(*ins)
    lam = ca.SX.sym("lam", out.shape[0])
    z = ca.vertcat(*ins[:n_var_inputs])
    H = ca.triu(ca.hessian(ca.dot(lam, out), z)[0])
    return ca.Function(f"hess_{fn.name()}", ins + [lam], [H])


def jacobian(fn: ca.Function, n_var_inputs: int) -> ca.Function:
    """J(inputs...) = ∂fn/∂(the first ``n_var_inputs`` inputs)."""
    ins = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
    out = fn(*ins)
    return ca.Function(f"jac_{fn.name()}", ins, [ca.jacobian(out, ca.vertcat(*ins[:n_var_inputs]))])


def mapped(fn: ca.Function, ncalls: int) -> ca.Function:
    """``fn`` over ``ncalls`` columns; threads pay off only for the heavy functions."""
    # a compiled function (solver.spacetime.compiled) carries its virtual-machine size
    size = getattr(fn, "vm_instructions", None)
    if ncalls > 1 and (fn.n_instructions() if size is None else size) > 20000 * MAP_THREADS:
        return fn.map(ncalls, "thread", MAP_THREADS)
    return fn.map(ncalls) if ncalls > 1 else fn


class Term:
    """One named kind of term: a generic function called ``ncalls`` times.

    ``zidx`` (nz, ncalls): global variable index of each entry of the vertcat of the
    variable inputs, per call; ``params``: the MX parameter inputs (one column per call);
    ``cost``: the outputs are summed into the objective; otherwise ``selected`` (call, row)
    pairs are constraint rows, starting at ``g_offset``.
    """

    def __init__(self, name: str, fn: ca.Function, nvar: int, zidx: np.ndarray, params: list,
                 *, cost: bool = False, hess_vars: int | None = None,
                 derivatives: tuple[ca.Function, ca.Function | None] | None = None) -> None:
        self.name, self.fn, self.nvar = name, fn, nvar
        self.zidx = np.asarray(zidx, dtype=int)
        self.params = params
        self.cost = cost
        self.hess_vars = nvar if hess_vars is None else hess_vars
        self.selected: list[tuple[int, int]] = []
        self.g_offset = 0
        #: (Hessian of the Lagrangian, Jacobian) when cached by the caller (per character)
        self.derivatives = derivatives

    @property
    def ncalls(self) -> int:
        return int(self.zidx.shape[1])

    def variables(self, x: ca.MX) -> list[ca.MX]:
        out, o = [], 0
        for i in range(self.nvar):
            s = self.fn.size1_in(i)
            out.append(ca.reshape(x[self.zidx[o : o + s].ravel(order="F").tolist()], s, self.ncalls))
            o += s
        return out

    def outputs(self, x: ca.MX) -> ca.MX:
        return mapped(self.fn, self.ncalls)(*self.variables(x), *self.params)


def assemble(terms: list[Term], x: ca.MX, p: ca.MX, g: ca.MX, nx: int, ng: int,
             extra_hessian: list | None = None) -> tuple[ca.Function, ca.Function, int, int]:
    """jac_g(x, p) = (g, ∂g/∂x) and hess_lag(x, p, lam_f, lam_g) = triu ∇²(lam_f f + lam_g·g)."""
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", ng)
    lam_ext = ca.vertcat(lam_g, 0)  # index ng -> a zero multiplier (rows not in the NLP)
    hblocks: list = []
    jblocks: list = []
    for t_ in terms:
        hf, jf = t_.derivatives or (lagrangian_hessian(t_.fn, t_.hess_vars), None)
        zvars = t_.variables(x)
        if t_.cost:
            LAM = ca.repmat(lam_f, 1, t_.ncalls)
        else:
            if not t_.selected:
                continue
            rowmap = np.full((t_.fn.size1_out(0), t_.ncalls), -1, dtype=int)
            for k, (c, r) in enumerate(t_.selected):
                rowmap[r, c] = t_.g_offset + k
            lam_idx = np.where(rowmap >= 0, rowmap, ng)
            LAM = ca.reshape(lam_ext[lam_idx.ravel(order="F").tolist()], t_.fn.size1_out(0), t_.ncalls)
            jf = jf or jacobian(t_.fn, t_.nvar)
            jv = mapped(jf, t_.ncalls)(*zvars, *t_.params)
            jblocks.append((jv, t_.zidx, jf.sparsity_out(0), rowmap))
        if hf.sparsity_out(0).nnz():
            h = mapped(hf, t_.ncalls)(*zvars, *t_.params, LAM)
            hblocks.append((h, t_.zidx, hf.sparsity_out(0), None))
    for vals, idx in extra_hessian or []:  # diagonal blocks: (values 1 x N, indices N)
        hblocks.append((vals(lam_f), np.asarray(idx)[None, :], ca.Sparsity.dense(1, 1), None))
    H = scatter(hblocks, nx, nx, symmetric=True)
    J = scatter(jblocks, ng, nx, symmetric=False)
    hess = ca.Function("nlp_hess_l", [x, p, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"], ["hess"])
    jac = ca.Function("nlp_jac_g", [x, p], [g, J], ["x", "p"], ["g", "jac_g_x"])
    return jac, hess, int(H.nnz()), int(J.nnz())


def scatter(blocks, nrows: int, ncols: int, *, symmetric: bool) -> ca.MX:
    """Sum mapped per-call derivative blocks into one global sparse matrix.

    Each block: (values (m x nz*N, repeated sparsity), zidx (nz, N) global column of each
    local column, local sparsity, rowmap (m, N) global row or -1, None = symmetric).
    """
    rows_all, cols_all, src_all, fac_all, parts = [], [], [], [], []
    offset = 0
    for vals, zidx, spz, rowmap in blocks:
        r, c = (np.asarray(v, dtype=int) for v in spz.get_triplet())
        nnz, ncall = len(r), zidx.shape[1]
        if nnz == 0:
            continue
        src = offset + np.arange(nnz * ncall).reshape(ncall, nnz).T  # (nnz, ncall)
        b = zidx[c]
        if symmetric:
            a = zidx[r]
            gr, gc = np.minimum(a, b), np.maximum(a, b)
            fac = np.where((r != c)[:, None] & (a == b), 2.0, 1.0)
            keep = np.ones_like(gr, dtype=bool)
        else:
            gr = rowmap[r]  # (nnz, ncall)
            gc = b
            fac = np.ones(gr.shape)
            keep = gr >= 0
        rows_all.append(gr[keep])
        cols_all.append(gc[keep])
        src_all.append(src[keep])
        fac_all.append(fac[keep])
        parts.append(ca.vec(vals.nz[:]))
        offset += nnz * ncall
    if not parts:
        return ca.MX(nrows, ncols)
    rows_g = np.concatenate(rows_all)
    cols_g = np.concatenate(cols_all)
    keys = cols_g.astype(np.int64) * nrows + rows_g
    uniq, inv = np.unique(keys, return_inverse=True)
    ucols, urows = np.divmod(uniq, nrows)  # sorted keys = CasADi's column-major order
    S = sps.csc_matrix((np.concatenate(fac_all), (inv, np.concatenate(src_all))), shape=(len(uniq), offset))
    S.sort_indices()
    Sd = ca.DM(ca.Sparsity(S.shape[0], S.shape[1], S.indptr.tolist(), S.indices.tolist()), S.data)
    pattern = ca.Sparsity.triplet(nrows, ncols, urows.tolist(), ucols.tolist())
    return ca.MX(pattern, ca.mtimes(Sd, ca.vertcat(*parts)))
