"""The per-pillar block preconditioner with its stacks on a device.

Same mathematics as `brushcore.numerics.linear.precondition.BlockInverse` (read
its docstring): exact inverses of each pillar's block, downdated on
detachment, with the balancing coarse space over pillars.  What differs is
where the work happens:

- the stacked inverses, the coarse vectors and the interaction matrices
  live in the backend's namespace, and are applied as one batched dense
  product (a GPU streams the (N, m, m) stack at memory bandwidth; the CPU
  class's packed BLAS path does not port);
- a detachment downdates every touched pillar in one batched Schur
  complement (a regular brush's event touches many pillars at once, and a
  Python loop over them cost more than the downdates on a card), and on a
  card the other pillars' warm start (`WarmStart`) is left to CG (see
  ``respond``);
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

from brushcore.numerics.platform.backend import Backend
from brushcore.numerics.halfspace.kernel import love_coefficient
from brushcore.numerics.linear.precondition import BlockInverse
from brushcore.numerics.linear.warm_start import WarmStart

#: Fraction of the device's free memory the stacks may take: the FFT
#: buffers, cuFFT work areas and CG vectors need the rest.
DEVICE_MEMORY_FRACTION = 0.5
#: ... and one batch of downdated blocks at most this fraction (a few
#: temporaries of its size live at once).
DOWNDATE_MEMORY_FRACTION = 0.05


class DeviceBlocks(BlockInverse):
    """`BlockInverse` whose arrays live in ``backend``'s namespace.

    Parameters
    ----------
    elements, pillar_of, n, compliance, h, e_star, coarse : as for `BlockInverse`
    backend : where the arrays live; mirrored grids are CPU-only
    """

    #: Bytes of touched blocks that one batched downdate takes at a time
    #: (its temporaries are a few times this), at most DOWNDATE_MEMORY_FRACTION
    #: of the card's free memory.
    DOWNDATE_CHUNK_BYTES = 2e9
    #: Largest pillar (elements) with dense blocks on a device, where they
    #: fit DEVICE_MEMORY_FRACTION of its free memory: a card streams the
    #: stack at memory bandwidth, and the alternative (Sherman-Morrison,
    #: `BrushOperator.precondition`) needs many times the applications.
    DEVICE_MAX_BLOCK = 8192

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
            block = xp.linalg.inv(self._device_block(group[0], np.arange(k)))
            for p in group:  # one inversion per shape, on the device
                self.inv[p, :k, :k] = block
        self._pos_host = self.pos
        self.pos = be.asarray(self.pos)
        self._work = xp.zeros(n_pillars * self.m, dtype=xp.float64)
        self._remaining = counts.copy()  # host: per-pillar counts are event data
        # a smaller card takes smaller batches: their temporaries stay beside the stack
        self._chunk_bytes = min(self.DOWNDATE_CHUNK_BYTES,
                                DOWNDATE_MEMORY_FRACTION * be.free_memory())
        # The other pillars' response to a detachment (`WarmStart`: the
        # neighbours' first order, the far field's warm start) saves
        # applications where one costs more than its host-side coefficient
        # lookups.  On a card it does not: 32 ms a detachment against 1.2 ms
        # an application, 22 of the 43 s of 16 x 16 at kbar 0.455 on 1024^2
        # (NVIDIA H200, 2026-12-04).  The strict namespace keeps it, so the
        # code stays checked for portability.
        self.respond = be.name != "gpu"
        self._drifted: set[int] = set()
        self.factorisations = 0
        self.interacting = 1 < n_pillars <= self.MAX_INTERACTION
        self.coarse = coarse and self.interacting and n_pillars <= self.MAX_COARSE
        self.warm_start = None  # below: `_refresh_rows` has no tilts to update yet
        if self.interacting:
            r, r_near = self._interaction(counts)
            self._r, self._r_near = be.asarray(r), be.asarray(r_near)
            self._z = xp.zeros((n_pillars, self.m), dtype=xp.float64)
            self._reach = xp.zeros((n_pillars, self.m), dtype=xp.float64)
            # a chunk at a time: abs() of the whole stack would double the peak
            # that `fits_device` budgets for
            for chunk in self._chunks(np.arange(n_pillars)):
                p = be.asarray(chunk.astype(np.int64))
                self._refresh_rows(p, xp.take(self.inv, p, axis=0))
            self.coupling = float(xp.max(self._r @ xp.sum(self._z, axis=1)))
            self.coarse = self.coarse and self.coupling >= self.COUPLING_PER_PILLAR * n_pillars
        if self.coarse:
            self._factorise()
        if self.interacting and self.respond:
            self.warm_start = WarmStart(self, counts, n)

    def _coefficient_table(self, off: np.ndarray, h: float, e_star: float) -> np.ndarray:
        """`BlockInverse._coefficient_table` evaluated on the device (n^2
        coefficients: seconds on a host core at n = 2048), kept there for
        the initial blocks and copied to the host for later lookups."""
        xp, be = self.backend.xp, self.backend
        d = be.asarray(off)
        self._table_device = love_coefficient(d[:, None], d[None, :], h, e_star, xp)
        return be.to_host(self._table_device)

    def _device_block(self, p: int, slots: np.ndarray) -> Any:
        """`BlockInverse._block` over pillar p's ``slots``, gathered on the
        device from its copy of the table (random brushes have a shape per
        pillar: m^2 host lookups each)."""
        xp, be = self.backend.xp, self.backend
        iy, ix = be.asarray(self._iyy[p, slots]), be.asarray(self._ixx[p, slots])
        k = slots.size
        at = (xp.abs(iy[:, None] - iy[None, :]) * self._table_device.shape[1]
              + xp.abs(ix[:, None] - ix[None, :]))
        table = xp.reshape(self._table_device, (-1,))
        return xp.reshape(xp.take(table, xp.reshape(at, (-1,))), (k, k)) + float(self._compliance[p])

    def _row(self, p: int) -> Any:
        return self._work[p * self.m:(p + 1) * self.m]

    def _set_row(self, p: int, values: Any) -> None:
        self._work[p * self.m:(p + 1) * self.m] = values

    def _subtract_all(self, values: Any) -> None:
        self._work -= self.backend.xp.reshape(values, (-1,))

    @classmethod
    def fits_device(cls, pillar_of: np.ndarray, backend: Backend,
                    max_block: int | None = None) -> bool:
        """Whether the stack fits half the device's free memory (and the block limit).

        Unlike the CPU's fixed budget this one reads the card: a GPU run's
        path may depend on the card, its results agree within CG tolerance.
        """
        max_block = cls.DEVICE_MAX_BLOCK if max_block is None else max_block
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
        # zero where a pillar has no elements, whatever the units (`coarse_inverse`)
        self._e_inverse = xp.linalg.inv(e) * live[:, None] * live[None, :]
        self._c_factor = self.backend.to_host(c)
        self._c_inverse = xp.where(dead, 0.0, 1.0 / xp.where(dead, 1.0, c))
        self.factorisations += 1

    def _pillars(self, elements: Any) -> tuple[np.ndarray, np.ndarray]:
        """Pillar and slot (host) of operator-order element indices (device)."""
        pos = self._pos_host[self.backend.to_host(elements)]
        return np.divmod(pos, self.m)

    def detach(self, elements: Any, stress: Any = None, attached_pos: Any = None) -> Any:
        """See `BlockInverse.detach`; the downdates run on the device, batched
        over the touched pillars (a regular brush's event touches many at once)."""
        xp, be = self.backend.xp, self.backend
        pil, slot = self._pillars(elements)
        if stress is not None:
            be.put(self._work, attached_pos, stress)
        touched = np.unique(pil)
        lost = np.bincount(pil, minlength=self._remaining.size)
        self._remaining -= lost
        respond = stress is not None and self.warm_start is not None
        live_before = self._live[touched].copy() if respond else None
        self._live[pil, slot] = False
        before = [xp.asarray(self._row(int(p)), copy=True) for p in touched] if respond else None
        whole = touched[self._remaining[touched] == 0]  # whole pillars let go
        for chunk in self._chunks(whole):
            self._zero_pillars(chunk, stress is not None)
        part = touched[self._remaining[touched] > 0]
        order = np.lexsort((slot, pil))
        first = np.searchsorted(pil[order], part)
        # Pillars losing a like number of slots go together, padded to a power of two.
        width = 1 << np.ceil(np.log2(lost[part])).astype(np.int64)
        for w in np.unique(width):
            group, starts = part[width == w], first[width == w]
            for chunk in self._chunks(np.arange(group.size)):
                ranks = np.arange(w)[None, :]
                valid = ranks < lost[group[chunk]][:, None]
                index = np.where(valid, starts[chunk][:, None] + ranks, 0)
                gone = np.where(valid, slot[order][index], 0)
                self._downdate(group[chunk], gone, valid, stress is not None)
        self._note_coarse_drift(touched)
        if stress is None:
            return None
        if respond:
            self.warm_start.respond(touched, live_before, before)
        work = self._work
        out = work[attached_pos]
        work[...] = 0.0
        return out

    def _chunks(self, items: np.ndarray) -> list[np.ndarray]:
        """``items`` in runs whose blocks take DOWNDATE_CHUNK_BYTES at most."""
        size = max(1, int(self._chunk_bytes // (8.0 * self.m * self.m)))
        return [items[i:i + size] for i in range(0, items.size, size)]

    def _downdate(self, pillars: np.ndarray, gone: np.ndarray, valid: np.ndarray,
                  with_work: bool) -> None:
        """Remove slots ``gone`` (t, k; where ``valid``) from the touched
        pillars' inverses in one batched Schur complement, as
        `brushcore.numerics.linear.stacks.remove_slots` does per pillar;
        with the stresses in `_work`, their exact local response too.
        Padding slots enter as identity rows, so they change nothing."""
        xp, be, m = self.backend.xp, self.backend, self.m
        t, k = gone.shape
        p = be.asarray(pillars.astype(np.int64))
        d = be.asarray(gone.astype(np.int64))
        v = be.asarray(valid.astype(np.float64))
        g = xp.take(self.inv, p, axis=0)  # (t, m, m)
        stack = xp.arange(t, dtype=xp.int64)
        at = (stack[:, None, None] * (m * m) + xp.arange(m, dtype=xp.int64)[None, :, None] * m
              + d[:, None, :])
        cols = xp.reshape(xp.take(xp.reshape(g, (-1,)), xp.reshape(at, (-1,))), (t, m, k))
        cols = cols * v[:, None, :]
        at = stack[:, None, None] * (m * k) + d[:, :, None] * k + xp.arange(k, dtype=xp.int64)
        gdd = xp.reshape(xp.take(xp.reshape(cols, (-1,)), xp.reshape(at, (-1,))), (t, k, k))
        gdd = gdd * v[:, :, None] + xp.eye(k, dtype=xp.float64)[None, :, :] * (1.0 - v)[:, :, None]
        rhs = xp.permute_dims(cols, (0, 2, 1))
        if with_work:
            w = xp.take(xp.reshape(self._work, (-1, m)), p, axis=0)  # (t, m)
            wd = xp.take(xp.reshape(w, (-1,)), xp.reshape(stack[:, None] * m + d, (-1,)))
            rhs = xp.concat([rhs, xp.reshape(wd, (t, k, 1)) * v[:, :, None]], axis=2)
        x = xp.linalg.solve(gdd, rhs)
        keep = be.asarray(self._live[pillars].astype(np.float64))  # after the detachment
        # zero rows and columns of D: exact, round-off removed
        g = (g - cols @ x[:, :, :m]) * keep[:, :, None] * keep[:, None, :]
        be.put(self.inv, p, g)
        if with_work:
            w = (w - (cols @ x[:, :, m:])[:, :, 0]) * keep
            be.put(self._work, self._stack_index(p), xp.reshape(w, (-1,)))
        self._refresh_rows(p, g)

    def _zero_pillars(self, pillars: np.ndarray, with_work: bool) -> None:
        """Pillars that let go entirely: zero inverses (and stresses)."""
        xp, be, m = self.backend.xp, self.backend, self.m
        p = be.asarray(pillars.astype(np.int64))
        g = xp.zeros((pillars.size, m, m), dtype=xp.float64)
        be.put(self.inv, p, g)
        if with_work:
            be.put(self._work, self._stack_index(p), xp.zeros(pillars.size * m, dtype=xp.float64))
        self._refresh_rows(p, g)

    def _stack_index(self, p: Any) -> Any:
        """Flat (N * m) positions of pillars p's slots, pillar by pillar."""
        xp, m = self.backend.xp, self.m
        return xp.reshape(p[:, None] * m + xp.arange(m, dtype=xp.int64)[None, :], (-1,))

    def attach(self, elements: Any) -> None:
        """See `BlockInverse.attach`: touched blocks gathered and inverted afresh
        on the device (O(m^3) there, where a host core took seconds a pillar
        at m of thousands; the CPU class borders its inverse instead)."""
        xp, be, m = self.backend.xp, self.backend, self.m
        pil, slot = self._pillars(elements)
        self._live[pil, slot] = True
        touched = np.unique(pil)
        for p in touched:
            live = np.flatnonzero(self._live[p])
            flat = xp.zeros(m * m, dtype=xp.float64)
            at = (live[:, None] * m + live[None, :]).reshape(-1)
            block = xp.linalg.inv(self._device_block(int(p), live))
            be.put(flat, be.asarray(at.astype(np.int64)), xp.reshape(block, (-1,)))
            self.inv[int(p), :, :] = xp.reshape(flat, (m, m))
        self._remaining += np.bincount(pil, minlength=self._remaining.size)
        for chunk in self._chunks(touched):
            p = self.backend.asarray(chunk.astype(np.int64))
            self._refresh_rows(p, self.backend.xp.take(self.inv, p, axis=0))
        self._note_coarse_drift(touched)

    def _refresh_rows(self, p: Any, g: Any) -> None:
        """Coarse vectors, reach and tilts of pillars p (device) from their
        new inverses g (t, m, m)."""
        if not self.interacting:
            return
        xp, be = self.backend.xp, self.backend
        be.put(self._z, p, xp.sum(g, axis=2))
        be.put(self._reach, p, xp.sum(xp.abs(g), axis=2))
        if self.warm_start is not None:
            self.warm_start.refresh(p, g)

    def _note_coarse_drift(self, touched: np.ndarray) -> None:
        """The coarse factor's drift check (`BlockInverse._note_drift`) for the touched pillars."""
        if self.coarse:
            xp, be = self.backend.xp, self.backend
            z = xp.take(self._z, be.asarray(touched.astype(np.int64)), axis=0)
            self._note_drift(touched, be.to_host(xp.sum(z, axis=1)))

    def reach(self) -> Any:
        """See `BlockInverse.reach` (kept up to date by `_refresh_rows` here)."""
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
