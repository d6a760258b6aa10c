"""The per-pillar block preconditioner with its stacks on a device.

Same mathematics as `brushcore.numerics.precondition.BlockInverse` (read
its docstring): exact inverses of each pillar's block, downdated on
detachment, with the balancing coarse space over pillars.  What differs is
where the work happens:

- the stacked inverses, the coarse vectors and the interaction matrices
  live in the backend's namespace, and are applied as one batched dense
  product (a GPU streams the (N, m, m) stack at memory bandwidth; the CPU
  class's packed BLAS path does not port);
- the coarse matrix E is inverted explicitly (the array API has no
  triangular solve) and applied as a matrix-vector product;
- geometry (stack slots, coordinates, the coefficient table) is computed
  once on the host, as the CPU class does; only event data (the slots of
  detaching elements, per-pillar scalars) crosses to the host afterwards.

Used for every backend but ``cpu``, which keeps `BlockInverse` and its
CPU-specialised kernels (and bit-identical results).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from brushcore.numerics.backend import Backend
from brushcore.numerics.precondition import BlockInverse

#: Fraction of the device's free memory the stacks may take: the FFT
#: buffers, cuFFT work areas and CG vectors need the rest.
DEVICE_MEMORY_FRACTION = 0.5


class DeviceBlocks(BlockInverse):
    """`BlockInverse` whose arrays live in ``backend``'s namespace.

    Parameters
    ----------
    elements, pillar_of, n, compliance, h, e_star, coarse : as for `BlockInverse`
    backend : where the arrays live; mirrored grids are CPU-only
    """

    def __init__(self, elements: np.ndarray, pillar_of: np.ndarray, n: int,
                 compliance: np.ndarray, h: float, e_star: float, coarse: bool = True,
                 *, backend: Backend) -> None:
        self.backend = be = backend
        xp = be.xp
        n_pillars = compliance.size
        counts = self._layout(elements, pillar_of, n, compliance, h, e_star, False)
        self.inv = xp.zeros((n_pillars, self.m, self.m), dtype=xp.float64)
        for group in self._shape_groups(counts):
            k = int(counts[group[0]])
            block = be.asarray(np.linalg.inv(self._block(group[0], np.arange(k))))
            for p in group:  # one host inversion per shape, copied on the device
                self.inv[p, :k, :k] = block
        self._pos_host = self.pos
        self.pos = be.asarray(self.pos)
        self._work = xp.zeros(n_pillars * self.m, dtype=xp.float64)
        self._remaining = counts.copy()  # host: per-pillar counts are event data
        self._drifted: set[int] = set()
        self.factorisations = 0
        self.interacting = 1 < n_pillars <= self.MAX_INTERACTION
        self.coarse = coarse and self.interacting and n_pillars <= self.MAX_COARSE
        if self.interacting:
            r, r_near = self._interaction(counts)
            self._r, self._r_near = be.asarray(r), be.asarray(r_near)
            self._z = xp.sum(self.inv, axis=2)
            self._reach = xp.sum(xp.abs(self.inv), axis=2)
            self.coupling = float(xp.max(self._r @ xp.sum(self._z, axis=1)))
            self.coarse = self.coarse and self.coupling >= self.COUPLING_PER_PILLAR * n_pillars
        if self.coarse:
            self._factorise()
        self._neighbours = self._near_pillars(counts, n) if self.interacting else None
        self._near_blocks = {}
        self._setup_far(counts)

    def _row(self, p: int) -> Any:
        return self._work[p * self.m:(p + 1) * self.m]

    def _set_row(self, p: int, values: Any) -> None:
        self._work[p * self.m:(p + 1) * self.m] = values

    def _subtract_all(self, values: Any) -> None:
        self._work -= self.backend.xp.reshape(values, (-1,))

    @classmethod
    def fits_device(cls, pillar_of: np.ndarray, backend: Backend,
                    max_block: int = 2500) -> bool:
        """Whether the stack fits half the device's free memory (and the block limit).

        Unlike the CPU's fixed budget this one reads the card: a GPU run's
        path may depend on the card, its results agree within CG tolerance.
        """
        m, stack_bytes = cls.stack_size(pillar_of)
        return m <= max_block and stack_bytes <= DEVICE_MEMORY_FRACTION * backend.free_memory()

    def _factorise(self) -> None:
        xp = self.backend.xp
        c = xp.sum(self._z, axis=1)
        dead = c <= 0.0
        live = xp.astype(~dead, xp.float64)
        e = c[:, None] * self._r * c[None, :] * live[:, None] * live[None, :]
        e = e + _diag(xp, xp.where(dead, 1.0, c))
        try:
            chol = xp.linalg.cholesky(e)
            ok = bool(xp.all(xp.isfinite(chol)))  # CuPy may return NaN instead of raising
        except np.linalg.LinAlgError:
            ok = False
        if not ok:  # see BlockInverse._factorise: the blocks alone remain valid
            self.coarse = False
            return
        self._e_inverse = xp.linalg.inv(e)
        self._c_factor = self.backend.to_host(c)
        self._c_inverse = xp.where(dead, 0.0, 1.0 / xp.where(dead, 1.0, c))
        self.factorisations += 1

    def _pillars(self, elements: Any) -> tuple[np.ndarray, np.ndarray]:
        """Pillar and slot (host) of operator-order element indices (device)."""
        pos = self._pos_host[self.backend.to_host(elements)]
        return np.divmod(pos, self.m)

    def detach(self, elements: Any, stress: Any = None, attached_pos: Any = None) -> Any:
        """See `BlockInverse.detach`; the downdates run on the device."""
        xp, be = self.backend.xp, self.backend
        pil, slot = self._pillars(elements)
        m, work = self.m, self._work
        if stress is not None:
            be.put(work, attached_pos, stress)
        touched = np.unique(pil)
        self._remaining -= np.bincount(pil, minlength=self._remaining.size)
        respond = stress is not None and self._neighbours is not None
        live_before = self._live[touched].copy() if respond else None
        self._live[pil, slot] = False
        before = [xp.asarray(self._row(int(p)), copy=True) for p in touched] if respond else None
        for p in touched:
            p = int(p)
            if self._remaining[p] == 0:  # the whole pillar lets go
                self.inv[p, :, :] = 0.0
                work[p * m:(p + 1) * m] = 0.0
                continue
            d = be.asarray(slot[pil == p])
            g = self.inv[p, :, :]
            cols = xp.take(g, d, axis=1)
            gdd = xp.take(cols, d, axis=0)
            rhs = xp.permute_dims(cols, (1, 0))
            if stress is not None:
                rhs = xp.concat([rhs, xp.take(work[p * m:(p + 1) * m], d)[:, None]], axis=1)
            x = xp.linalg.solve(gdd, rhs)
            keep = be.asarray(self._live[p].astype(float))
            g = (g - cols @ x[:, :m]) * keep[:, None] * keep[None, :]
            self.inv[p, :, :] = g  # zero rows and columns of D: exact, round-off removed
            if stress is not None:
                work[p * m:(p + 1) * m] = (work[p * m:(p + 1) * m] - cols @ x[:, m]) * keep
        self._refresh(touched)
        if stress is None:
            return None
        if respond:
            sources = self._neighbour_response(touched, live_before, before)
            if self._far:
                self._far_response(sources)
        out = work[attached_pos]
        work[...] = 0.0
        return out

    def attach(self, elements: Any) -> None:
        """See `BlockInverse.attach`: touched blocks inverted afresh (on the host,
        from host geometry) and copied to the device."""
        pil, slot = self._pillars(elements)
        self._live[pil, slot] = True
        touched = np.unique(pil)
        for p in touched:
            live = np.flatnonzero(self._live[p])
            g = np.zeros((self.m, self.m))
            g[np.ix_(live, live)] = np.linalg.inv(self._block(p, live))
            self.inv[int(p), :, :] = self.backend.asarray(g)
        self._remaining += np.bincount(pil, minlength=self._remaining.size)
        self._refresh(touched)

    def _refresh(self, touched: np.ndarray) -> None:
        """Coarse vectors and (when drifted) the coarse factor of changed pillars."""
        xp = self.backend.xp
        if self.interacting:
            for p in touched:
                self._z[int(p), :] = xp.sum(self.inv[int(p), :, :], axis=1)
                self._reach[int(p), :] = xp.sum(xp.abs(self.inv[int(p), :, :]), axis=1)
                if self._far:
                    self._tilt[int(p), :, :] = self.inv[int(p), :, :] @ self._tilt_basis[int(p), :, :]
        if self.coarse:
            idx = self.backend.asarray(touched.astype(np.int64))
            self._note_drift(touched, self.backend.to_host(
                xp.sum(xp.take(self._z, idx, axis=0), axis=1)))

    def reach(self) -> Any:
        """See `BlockInverse.reach` (kept up to date by `_refresh` here)."""
        return self._reach

    def far_field_uncertainty(self, pillar_change: Any, attached_pos: Any) -> Any:
        """See `BlockInverse.far_field_uncertainty`."""
        xp = self.backend.xp
        if not self.interacting:
            if self.inv.shape[0] > 1:
                return None
            return xp.zeros(attached_pos.shape[0], dtype=xp.float64)
        shift = self._r_near @ xp.abs(pillar_change)
        return xp.reshape(self._reach * shift[:, None], (-1,))[attached_pos]

    def apply(self, r: Any, attached_pos: Any) -> Any:
        """See `BlockInverse.apply`: one batched product over all pillars."""
        xp, be = self.backend.xp, self.backend
        be.put(self._work, attached_pos, r)
        if self.coarse:
            t = xp.sum(self._z * xp.reshape(self._work, (-1, self.m)), axis=1)  # Z^T r
            y1 = self._e_inverse @ t
            be.put(self._work, attached_pos, r - (t * self._c_inverse)[attached_pos // self.m])
        w = xp.reshape(self._work, (-1, self.m))
        z = xp.matmul(self.inv, w[:, :, None])[:, :, 0]
        self._work[...] = 0.0
        if self.coarse:
            z = z + self._z * (y1 - xp.sum(z, axis=1) * self._c_inverse)[:, None]
        return xp.reshape(z, (-1,))[attached_pos]


def _diag(xp: Any, v: Any) -> Any:
    """A diagonal matrix from a vector (the array API has no ``diag``)."""
    n = v.shape[0]
    eye = xp.eye(n, dtype=xp.float64)
    return eye * v[None, :]
