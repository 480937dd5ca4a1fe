"""The PBM's rates and stages in plain numpy: the test oracle of the compiled backend
(``pbmdem.pbm._compiled``, the library's one implementation).

* :func:`aggregation_totals`: the aggregation rates as one precomputed sparse map (scipy.sparse,
  block-diagonal over the ordered-pair rates R_ij = beta_ij N_i N_j, RL_ij = beta_ij L_i N_j,
  RG_ij = beta_ij G_i N_j) followed by the scheme's placement of the births. It adds the same
  products in the same order as the compiled loop, so the two agree to the bit.
* :func:`breakage_totals`: the breakage rates as matrix products with the fragment tables,
  births placed by the same cell-average split (equal to the compiled loop to round-off).
* :func:`success`, :func:`spraying`, :func:`consolidation`: the success models and the other
  rate processes as their formulas.
* :func:`class_rates` and :func:`ssp_step`: the rates of a class state and one SSP Runge-Kutta
  step, composed of the above (the same operations as the compiled ones).

This was the library's own numpy path before the compiled backend became the only one.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from scipy import sparse


class _Pairs:
    """The ordered pairs of an aggregation operator ``op`` (from its public target matrix)."""

    def __init__(self, op):
        self.K, self.M, self.xr = op.K, op.M, op.xr
        vc = op.class_volumes
        self.I, self.J = np.divmod(np.arange(self.M**2), self.M)
        self.S = vc[self.I] + vc[self.J]
        self.T = op.target_matrix.ravel()
        self.ok = self.T >= 0
        self.cols = np.arange(self.M**2)


def _cell_average_rows(p: _Pairs):
    """(rows, cols, values) of the number block and of the liquid (gas) block: rows 0..K-1 the
    births per cell B_c (1/2 per ordered pair), rows K..2K-1 their first moment D_c."""
    cols, t = p.cols[p.ok], p.T[p.ok]
    number = (
        np.concatenate([t, p.K + t]),
        np.concatenate([cols, cols]),
        np.concatenate([np.full(t.size, 0.5), 0.5 * (p.S[p.ok] / p.xr[t] - 1.0)]),
    )
    return number, (t, cols, np.ones(cols.size))


def _fixed_pivot_rows(p: _Pairs):
    """(rows, cols, values) of the number and the liquid (gas) blocks: every aggregate split
    between the two pivots around it (number and solid exact)."""
    cols, s, xr = p.cols[p.ok], p.S[p.ok], p.xr
    lo = np.clip(np.searchsorted(xr, s, side="right") - 1, 0, p.K - 2)
    up_number = (s - xr[lo]) / (xr[lo + 1] - xr[lo])
    up_solid = up_number * xr[lo + 1] / s
    rows, cc = np.concatenate([lo, lo + 1]), np.concatenate([cols, cols])
    number = (rows, cc, 0.5 * np.concatenate([1.0 - up_number, up_number]))
    return number, (rows, cc, np.concatenate([1.0 - up_solid, up_solid]))


def sparse_map(op):
    """The sparse map of :func:`aggregation_totals`: 3 blocks (R, RL, RG) of 2K + M + 1 rows: [0, 2K)
    the scheme's rows, [2K, 2K + M) the deaths of the M classes, 2K + M the refused solid (R
    block only, x_0 units)."""
    p = _Pairs(op)
    K, M = p.K, p.M
    number, liquid = (_cell_average_rows if op.name == "cell_average" else _fixed_pivot_rows)(p)
    R = 2 * K + M + 1
    dr, dc = 2 * K + p.I[p.ok], p.cols[p.ok]
    refused = ~p.ok
    blocks = []
    for b, (rows, cc, vals) in enumerate((number, liquid, liquid)):
        if b == 0:
            extra_r = np.concatenate([dr, np.full(int(refused.sum()), 2 * K + M)])
            extra_c = np.concatenate([dc, p.cols[refused]])
            extra_v = np.concatenate([np.ones(dr.size), 0.5 * p.S[refused]])
        else:
            extra_r, extra_c, extra_v = dr, dc, np.ones(dr.size)
        blocks.append(
            sparse.csr_matrix(
                (np.concatenate([vals, extra_v]), (np.concatenate([rows, extra_r]), np.concatenate([cc, extra_c]))),
                shape=(R, M * M),
            )
        )
    m = sparse.block_diag(blocks, format="csr")
    m.sum_duplicates()
    m.sort_indices()
    return m


def _cell_average_births(op, Y):
    """(3, K) births: the births of every cell split between its pivot and a neighbour so that
    number and solid are exact; liquid and gas follow the solid."""
    K, xr = op.K, op.xr
    dx_up = np.append(xr[1:] - xr[:-1], np.inf)
    dx_down = np.insert(xr[1:] - xr[:-1], 0, np.inf)
    ru = np.append(xr[1:] / xr[:-1], 0.0)
    rd = np.insert(xr[:-1] / xr[1:], 0, 0.0)
    A = Y[:, :K]
    B, D = A[0], Y[0, K : 2 * K]
    up = np.maximum(D, 0.0) * (xr / dx_up)
    down = np.minimum(D, 0.0) * (-xr / dx_down)
    V = B + D
    inv = np.divide(1.0, V, out=np.zeros(K), where=V > 0)
    mu, md = np.empty((3, K)), np.empty((3, K))
    mu[0], md[0] = up, down
    np.multiply(A[1:], up * ru * inv, out=mu[1:])
    np.multiply(A[1:], down * rd * inv, out=md[1:])
    out = A - mu - md
    out[:, 1:] += mu[:, :-1]
    out[:, :-1] += md[:, 1:]
    return out


def aggregation_totals(op, beta, nlg, m=None):
    """(d (3, M), refused solid rate) of the aggregation operator ``op`` with kernel ``beta`` (M,
    M) and class totals ``nlg`` (3, M); ``m``: its :func:`sparse_map` (built if not given)."""
    m = sparse_map(op) if m is None else m
    K, M = op.K, op.M
    U = nlg[:, :, None] * (beta * nlg[0])  # R, RL, RG
    Y = (m @ U.reshape(-1)).reshape(3, -1)
    d = -Y[:, 2 * K : 2 * K + M]
    d[:, :K] += _cell_average_births(op, Y) if op.name == "cell_average" else Y[:, :K]
    return d, float(Y[0, 2 * K + M])


def granule_porosity(S: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Intra-granular porosity eps = G / (S + G) of the granules of each bin (G the pore volume,
    wet or dry: docs/pbm.md); NaN where a bin holds no solid (no granules). The numpy form of
    ``_compiled.granule_porosity``, which the model uses."""
    S, G = np.broadcast_arrays(np.asarray(S, float), np.asarray(G, float))
    return np.divide(G, S + G, out=np.full(S.shape, np.nan), where=S > 0)


def bin_input(model, t, N, L, G):
    """The KernelInput of a one-dimensional model at the per-bin totals (t, N, L, G) (L, G in m3 or
    any unit: only ratios are used)."""
    from pbmdem.pbm.kernels import KernelInput
    from pbmdem.pbm.state import surface_fraction

    g, S = model.grid, N * model.grid.x
    phi, eps = surface_fraction(S, L, G), granule_porosity(S, G)
    return KernelInput(t=t, volumes=g.x, diameters=g.d, numbers=N, surface_fraction=phi, rpm=model.rpm, porosity=eps)


def compiled_totals(op, beta, nlg):
    """The library's compiled aggregation totals of the operator ``op`` (``_compiled.aggregation_totals``
    on its arrays, no success probability): ``(d, refused)``, ``d`` (3, M) a fresh array, the refused
    solid rate in units of x_0."""
    from pbmdem.pbm import _compiled

    d, beta, nlg = np.empty((3, op.M)), np.ascontiguousarray(beta, dtype=float), np.ascontiguousarray(nlg, dtype=float)
    refused = _compiled.aggregation_totals(beta, np.ones(op.M), False, nlg, *op.compiled_arrays(), d)
    return d, refused


def breakage_totals(xr, sel, tab, nlg):
    """(3, M) breakage rates of the class totals ``nlg`` (3, M) on the pivots ``xr`` (K,, units of
    x_0): the K pivot classes die at the selection rates ``sel`` (K,) with their liquid and gas;
    the fragments of ``tab`` (3, K, K: number, first moment about x_i, solid share per parent)
    are born per cell and placed by the cell-average split."""
    K = xr.size
    R = sel * nlg[:, :K]  # events, and the liquid and gas they carry
    Y = np.zeros((3, 2 * K))
    Y[0, :K], Y[0, K:] = tab[0] @ R[0], tab[1] @ R[0]
    Y[1:, :K] = R[1:] @ tab[2].T
    d = np.zeros(nlg.shape)
    d[:, :K] = _cell_average_births(SimpleNamespace(K=K, xr=xr), Y) - R
    return d


def success(model, threshold, width, phi):
    """p(phi) of the success models."""
    phi = np.asarray(phi, float)
    if model == "always":
        return np.ones_like(phi)
    if model == "step":
        return (phi >= threshold).astype(float)
    z = np.clip((phi - threshold) / width, -700, 700)
    return 1.0 / (1.0 + np.exp(-z))


def surface_fraction(nlg, xc):
    """max(L - G, 0) / (N x + max(L, G)) per class (0 if empty)."""
    N, L, G = nlg
    V = N * xc + np.maximum(L, G)
    return np.divide(np.maximum(L - G, 0.0), V, out=np.zeros(V.shape), where=V > 0)


def spraying(nlg, rate, weight):
    """dL: ``rate`` shared in proportion to N_k w_k."""
    w = nlg[0] * weight
    total = np.cumsum(w)[-1]  # summed in order (np.sum sums pairwise)
    return np.zeros_like(w) if total <= 0 or rate <= 0 else (rate / total) * w


def consolidation(nlg, rate, gas_min):
    """dG = -c (G_k - G_min,k N_k)."""
    return -rate * (nlg[2] - gas_min * nlg[0])


def class_rates(
    op, u, beta, model="always", threshold=0.0, width=1.0, xc=None, spray=(0.0, None), consol=(0.0, None), brk=None
):
    """Rates (3M,) and tallies (refused solid rate, fragments merged below the first pivot and
    their solid per second) of the class state u = [N, L, G] (3M,) with the kernel beta_ij
    p(phi_i) p(phi_j) (``model``), spraying (rate, weights), consolidation (rate, G_min) and
    breakage ``brk`` (selection (K,), fragment tables[, fragments below x_0 per breakage (2, K)])
    or None."""
    nlg = u.reshape(3, op.M)
    if model != "always":
        p = success(model, threshold, width, surface_fraction(nlg, op.class_volumes if xc is None else xc))
        beta = beta * np.outer(p, p)
    d, refused = aggregation_totals(op, beta, nlg)
    tally = np.array([refused, 0.0, 0.0])
    if brk is not None:
        d += breakage_totals(op.xr, *brk[:2], nlg)
        if len(brk) > 2:  # the fragments below the first pivot per breakage (2, K): their rates
            tally[1:] = brk[2] @ (brk[0] * nlg[0, : op.K])
    if spray[0] > 0:
        d[1] += spraying(nlg, *spray)
    if consol[0] > 0:
        d[2] += consolidation(nlg, *consol)
    return d.reshape(-1), tally


def ssp_step(rates, u, dt, order):
    """One SSP Runge-Kutta step of size dt from u with ``rates(u) -> (rates, tallies)``: (new
    state, embedded lower-order state or None, tallies of the step), increment forms."""
    k1, r1 = rates(u)
    u1 = u + dt * k1
    if order == 1 or (u1 < 0).any():
        return u1, None, r1
    k2, r2 = rates(u1)
    k12 = k1 + k2
    u_h = u + (0.5 * dt) * k12  # Heun (SSP-RK2)
    if order == 2:
        return u_h, u1, 0.5 * (r1 + r2)
    u2 = u + (0.25 * dt) * k12  # SSP-RK3 (Shu & Osher 1988)
    if (u2 < 0).any():
        return u2, u_h, r1
    k3, r3 = rates(u2)
    return u + (dt / 6.0) * (k12 + 4.0 * k3), u_h, (r1 + r2 + 4.0 * r3) / 6.0
