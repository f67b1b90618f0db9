"""Symmetric positive-definite block systems with an envelope (variable band) structure.

The smoother's reduced pose system is block tridiagonal (observations' pose information, motion factors) minus one dense
rank-3 term per landmark over the consecutive frames that see it (its Schur complement term): frame ``l`` is coupled
only with frames back to the first frame of the oldest track seen at ``l``, an *envelope*. A Cholesky factor has no fill
outside it; the factorisation loops over block columns on a dense *front* (the frames ``i .. reach[i]`` still coupled to
column ``i``), ``J = i+1 .. reach[i]``, in about ``sum_i 6^3 (reach[i] - i)^2`` flops instead of ``(6T)^3 / 3``::

    L_ii = chol(A_ii),   L_Ji = A_Ji L_ii^{-T},   A_JJ <- A_JJ - L_Ji L_Ji^T

Each landmark's term enters the front with its last frame, before any of its block columns is eliminated (the
Schur complement is never stored). The marginals, diagonal blocks of ``Sigma = A^{-1}``, come from the same factor
by the backward recursion of Takahashi et al. (from ``Sigma L = L^{-T}``, ``i = n-1 .. 0``; it needs ``Sigma``
only inside the envelope)::

    Sigma_Ji = -Sigma_JJ L_Ji L_ii^{-1},   Sigma_ii = L_ii^{-T} L_ii^{-1} - Sigma_Ji^T L_Ji L_ii^{-1}

Block rows are processed in groups of :data:`GROUP` (supernodes).
"""

from dataclasses import dataclass

import numpy as np

__all__ = ["EnvelopeSystem", "EnvelopeFactor", "envelope_reach", "cholesky", "solve", "inverse_diagonal",
           "to_dense"]


@dataclass
class EnvelopeSystem:
    """``A = tridiag(sub, diag, sub^T) - sum_k P_k V_k V_k^T P_k^T``, a symmetric block matrix.

    Correction ``k`` covers the block rows ``lo[k] .. hi[k]`` (``P_k`` places it there).

    Attributes
    ----------
    diag, sub : ndarray, shape (n, b, b), (n - 1, b, b)
        Symmetric diagonal blocks ``A[l, l]`` and ``A[l + 1, l]``, before corrections.
    lo, hi, start, rows : ndarray of int, shape (K,) each; ndarray, shape (S, b, r)
        Correction ``k`` is ``rows[start[k] : start[k] + hi[k] - lo[k] + 1]``; ``rows`` holds the ``V_k``, one
        ``(b, r)`` slice per block row (zero slices are allowed).
    """

    diag: np.ndarray
    sub: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    start: np.ndarray
    rows: np.ndarray

    @property
    def num_blocks(self):
        """n, the number of block rows."""
        return len(self.diag)

    def correction(self, k):
        """``V_k`` as a dense matrix of shape ``(b (hi - lo + 1), r)``."""
        stop = self.start[k] + self.hi[k] - self.lo[k] + 1
        return self.rows[self.start[k]:stop].reshape(-1, self.rows.shape[-1])


@dataclass
class EnvelopeFactor:
    """Block Cholesky factor ``A = L L^T`` of an :class:`EnvelopeSystem`, by groups of block rows.

    Attributes
    ----------
    lo, hi, reach : ndarray of int, shape (G,)
        First and last block row of each group, and the last block row coupled to it (``>= hi``).
    diag_inv, below : list of ndarray
        ``L_gg^{-1}``, shape ``(b n_g, b n_g)``; ``L_Jg`` for ``J = hi + 1 .. reach``, ``(b (reach - hi), b n_g)``.
    """

    lo: np.ndarray
    hi: np.ndarray
    reach: np.ndarray
    diag_inv: list
    below: list
    block_size: int


#: Block rows per group (supernode) of the factorisation.
GROUP = 8


def envelope_reach(system):
    """Last block row coupled to each column, (n,): ``max(i + 1, hi[k] for lo[k] <= i)``, clipped, nondecreasing."""
    n = system.num_blocks
    last = np.minimum(np.arange(n) + 1, n - 1)
    if len(system.lo):
        np.maximum.at(last, system.lo, system.hi)
    return np.maximum.accumulate(last)


class _Front:
    """A dense square buffer holding a sliding range of block rows/columns (the front)."""

    def __init__(self, width, block_size):
        self.b = block_size
        self.size = width + 1 + max(2 * GROUP, width // 4)  # slack: shift only every so many steps
        self.M = np.zeros((self.b * self.size, self.b * self.size))
        self.base = 0

    def fits(self, lo, hi):
        """True if block rows ``lo .. hi`` lie inside the buffer."""
        return self.base <= lo and hi < self.base + self.size

    def move(self, keep_lo, keep_hi, new_base):
        """Re-base the buffer at block ``new_base``, keeping the blocks ``keep_lo .. keep_hi``."""
        b = self.b
        old = slice(b * (keep_lo - self.base), b * (keep_hi - self.base + 1))
        new = slice(b * (keep_lo - new_base), b * (keep_hi - new_base + 1))
        self.M[new, new] = self.M[old, old].copy()
        self.base = new_base

    def span(self, lo, hi):
        """Scalar slice of block rows ``lo .. hi`` (inclusive)."""
        return slice(self.b * (lo - self.base), self.b * (hi - self.base + 1))


@dataclass
class _CorrectionPlan:
    """The corrections ordered by last block row, with their rows concatenated in that order."""

    order: np.ndarray  # correction indices by last row
    by_row: np.ndarray  # corrections ending at row r: order[by_row[r] : by_row[r + 1]]
    offset: np.ndarray  # rows of the j-th ordered correction: concatenated[offset[j] : offset[j + 1]]
    slot: np.ndarray  # index into system.rows of each concatenated row
    owner: np.ndarray  # ordered position j of each concatenated row's correction
    row: np.ndarray  # block row of each concatenated row

    @classmethod
    def build(cls, system):
        order = np.argsort(system.hi, kind="stable")
        count = (system.hi - system.lo + 1)[order]
        offset = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
        owner = np.repeat(np.arange(len(order)), count)
        within = np.arange(offset[-1]) - offset[owner]
        return cls(order, np.searchsorted(system.hi[order], np.arange(system.num_blocks + 1)), offset,
                   system.start[order][owner] + within, owner, system.lo[order][owner] + within)


#: Corrections whose first rows differ by less than this many block rows share one update.
BUCKET = 16


def _add_corrections(front, system, plan, first_row, last_row):
    """Subtract ``V_k V_k^T`` of the corrections ending in ``first_row .. last_row``, in one rank-``3K``
    update per :data:`BUCKET` of similar first rows (each front entry touched a few times, not per landmark).
    """
    a, b = plan.by_row[first_row], plan.by_row[last_row + 1]
    if a == b:
        return
    ks = plan.order[a:b]
    lo, hi = system.lo[ks], system.hi[ks]
    by_lo = np.argsort(lo, kind="stable")
    rank = np.empty(b - a, dtype=np.int64)
    rank[by_lo] = np.arange(b - a)
    top = lo.min()
    rows = slice(plan.offset[a], plan.offset[b])
    r = system.rows.shape[-1]
    packed = np.zeros((last_row - top + 1, system.rows.shape[1], b - a, r))
    packed[plan.row[rows] - top, :, rank[plan.owner[rows] - a], :] = system.rows[plan.slot[rows]]
    packed = packed.reshape(-1, (b - a) * r)
    lo_sorted, hi_sorted = lo[by_lo], hi[by_lo]
    cuts = np.flatnonzero(np.diff((lo_sorted - top) // BUCKET)) + 1
    bs = front.b
    for j0, j1 in zip(np.r_[0, cuts], np.r_[cuts, b - a]):
        r0, r1 = lo_sorted[j0], hi_sorted[j0:j1].max()
        V = packed[bs * (r0 - top):bs * (r1 - top + 1), r * j0:r * j1]
        span = front.span(r0, r1)
        front.M[span, span] -= V @ V.T


def _load_rows(front, system, top, first_row, last_row):
    """Bring block rows ``first_row .. last_row`` into the front, clearing stale entries from ``top`` on."""
    b, k = front.b, last_row - first_row + 1
    new, used = front.span(first_row, last_row), front.span(top, last_row)
    front.M[new, used] = 0.0
    front.M[used, new] = 0.0
    blocks = front.M[new, new].reshape(k, b, k, b)  # a view: (row, i, column, j)
    i = np.arange(k)
    blocks[i, :, i, :] = system.diag[first_row:last_row + 1]
    blocks[i[1:], :, i[:-1], :] = system.sub[first_row:last_row]
    blocks[i[:-1], :, i[1:], :] = np.swapaxes(system.sub[first_row:last_row], 1, 2)
    if first_row > top:
        r, p = front.span(first_row, first_row), front.span(first_row - 1, first_row - 1)
        front.M[r, p] = system.sub[first_row - 1]
        front.M[p, r] = system.sub[first_row - 1].T


def cholesky(system, group=GROUP):
    """:class:`EnvelopeFactor` of ``system``, ``group`` block rows at a time; LinAlgError if not positive definite."""
    n, b = system.num_blocks, system.diag.shape[1]
    lo = np.arange(0, n, group)
    hi = np.minimum(lo + group, n) - 1
    reach = envelope_reach(system)[hi]
    plan = _CorrectionPlan.build(system)
    front = _Front(int((reach - lo).max(initial=0)), b)
    diag_inv, below = [], []
    loaded = -1
    for s, e, c in zip(lo, hi, reach):
        if not front.fits(s, c):
            front.move(s, loaded, s)
        if loaded < c:
            _load_rows(front, system, s, loaded + 1, c)
            _add_corrections(front, system, plan, loaded + 1, c)
            loaded = c
        d, J = front.span(s, e), front.span(e + 1, c)
        diag_inv.append(np.linalg.inv(np.linalg.cholesky(front.M[d, d])))
        L_J = front.M[J, d] @ diag_inv[-1].T
        if L_J.size:
            front.M[J, J] -= L_J @ L_J.T
        below.append(L_J)
    return EnvelopeFactor(lo, hi, reach, diag_inv, below, b)


def solve(factor, rhs):
    """Solve ``A x = rhs`` with the factor of :func:`cholesky`; ``rhs`` and ``x`` have shape (n, b)."""
    y = np.array(rhs, dtype=float)
    groups = list(zip(factor.lo, factor.hi, factor.reach, factor.diag_inv, factor.below))
    for s, e, c, L_inv, L_J in groups:  # forward: L y = rhs
        y[s:e + 1] = (L_inv @ y[s:e + 1].ravel()).reshape(-1, factor.block_size)
        if c > e:
            y[e + 1:c + 1] -= (L_J @ y[s:e + 1].ravel()).reshape(c - e, -1)
    for s, e, c, L_inv, L_J in reversed(groups):  # backward: L^T x = y
        y_g = y[s:e + 1].ravel()
        if c > e:
            y_g = y_g - L_J.T @ y[e + 1:c + 1].ravel()
        y[s:e + 1] = (L_inv.T @ y_g).reshape(-1, factor.block_size)
    return y


def inverse_diagonal(factor, visit=None):
    """Diagonal blocks of ``A^{-1}``, (n, b, b), by the Takahashi recursion, group by group.

    ``visit(lo, hi, Sigma_front)``, if given, gets ``A^{-1}`` on the block rows and columns
    ``lo .. reach`` of each group (a view: copy what you keep); the landmark covariances use it.
    """
    b = factor.block_size
    n = int(factor.hi[-1]) + 1 if len(factor.hi) else 0
    front = _Front(int((factor.reach - factor.lo).max(initial=0)), b)
    front.base = max(0, n - front.size)
    out = np.empty((n, b, b))
    for s, e, c, L_inv, L_J in reversed(list(zip(factor.lo, factor.hi, factor.reach, factor.diag_inv,
                                                 factor.below))):
        if not front.fits(s, c):
            front.move(e + 1, c, max(0, c + 1 - front.size))
        d, J = front.span(s, e), front.span(e + 1, c)
        Z = L_J @ L_inv
        Sigma_J = -front.M[J, J] @ Z
        Sigma_g = L_inv.T @ L_inv - Sigma_J.T @ Z
        front.M[d, d] = 0.5 * (Sigma_g + Sigma_g.T)
        front.M[J, d] = Sigma_J
        front.M[d, J] = Sigma_J.T
        k = np.arange(e - s + 1)
        out[s:e + 1] = front.M[d, d].reshape(e - s + 1, b, e - s + 1, b)[k, :, k, :]
        if visit is not None:
            visit(s, e, front.M[front.span(s, c), front.span(s, c)])
    return out


def to_dense(system):
    """The full matrix of an :class:`EnvelopeSystem`, shape (n b, n b) (tests, small systems)."""
    n, b = system.num_blocks, system.diag.shape[1]
    A = np.zeros((n * b, n * b))
    for row in range(n):
        A[row * b:(row + 1) * b, row * b:(row + 1) * b] = system.diag[row]
        if row > 0:
            A[row * b:(row + 1) * b, (row - 1) * b:row * b] = system.sub[row - 1]
            A[(row - 1) * b:row * b, row * b:(row + 1) * b] = system.sub[row - 1].T
    for k in range(len(system.lo)):
        V = system.correction(k)
        lo = system.lo[k] * b
        A[lo:lo + len(V), lo:lo + len(V)] -= V @ V.T
    return A
