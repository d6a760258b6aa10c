"""The warm start a detachment gives: the other pillars' answer to a pillar's change.

When elements detach, `BlockInverse.detach`
(`brushcore.numerics.linear.precondition`) solves the pillar that lost them
exactly with the others held (the downdate's Schur complement).  How the
other pillars answer that change is estimated here, from the same block
inverses, for the global solve that follows to start from:

- its nearest pillars add their first-order response to that change, from
  direct sums of influence coefficients (`WarmStart._neighbour_response`);
- where the pillars couple weakly, every other pillar adds its response to
  the multipole expansion of the changes' field (`WarmStart._far_response`,
  `brushcore.numerics.halfspace.multipole`).

A warm start, not a bound: the global solve corrects what it misses.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from brushcore.numerics.halfspace.multipole import field_terms


class WarmStart:
    """The other pillars' response to a detachment, for the blocks that own it.

    Parameters
    ----------
    blocks : the block preconditioner (`BlockInverse` or `DeviceBlocks`) with
        its pillar interaction set up (`_centroids`, `coupling`): the warm
        start reads its inverses, geometry and coefficient lookups, and
        writes the stacked stresses through its work-vector accessors
        (`_row`, `_set_row`, `_subtract_all`)
    counts : elements per pillar when the blocks were built
    n : grid size (elements per side)

    Attributes
    ----------
    neighbours : per pillar, the nearest pillars whose first-order response
        `respond` adds (at most NEIGHBOURS, within the pair budget)
    local : per pillar, the LOCAL nearest pillars, which answer the field
        of a neighbour's response (`_far_response`)
    far : whether the far-field response is on (coupling below
        FAR_RESPONSE_MAX_COUPLING)
    tilt_basis, tilt : while `far`, the second-order fields over each pillar
        and each pillar's response to them (`_tilts`), in the stacks' namespace
    """

    #: Largest `coupling` with the far-field warm start (`_far_response`).
    #: The first-order answer misses the pillars' collective one, by a
    #: smooth error of one sign that the preconditioned residual underrates,
    #: so CG may stop with it: measured, F_ad 4e-4 from exact mode for 24 x
    #: 24 at kbar 1e-2 (coupling 3.6), 4.1e-5 for the rigid 4 x 4 brush on
    #: 128^2 (0.75), W 2.2e-5 for random 30 at kbar 1e-2 on 96^2 (0.25),
    #: and more applications, not fewer, for 16 x 16 at kbar 0.455 (5.4).
    #: At 0.18 (random 1620 at kbar 1e-4, 512^2) F_ad and W stay within
    #: 2.5e-6 and 3.9e-7 of exact mode, with 23 % fewer applications.
    FAR_RESPONSE_MAX_COUPLING = 0.2

    #: Pillars that answer the field of a neighbour's first-order response
    #: (`_far_response`): a second-order change, felt near it only.
    LOCAL = 32

    #: Most neighbours whose first-order response follows a pillar's change.
    NEIGHBOURS = 12
    #: Coefficient pairs per changed pillar for that response, per element of
    #: the grid: it must cost well under one application (~n^2 log n).
    NEIGHBOUR_PAIRS_PER_ELEMENT = 0.25

    #: Pillars whose neighbour coefficients `_near_block` keeps: a cascade
    #: touches the same pillar for several rounds in a row.
    NEAR_BLOCKS_KEPT = 4

    # blocks: Any, not BlockInverse: the blocks import this module, and
    # DeviceBlocks serves as well
    def __init__(self, blocks: Any, counts: np.ndarray, n: int) -> None:
        # a weak reference: the blocks own this object, and a cycle kept their
        # stacks (up to MEMORY_BUDGET) alive after a run until the garbage
        # collector ran (a notebook's sixth run at 256^2: 207 MB against 138)
        self.blocks = weakref.proxy(blocks)
        self.neighbours, self.local = self._near_pillars(counts, n)
        self._near_blocks: dict[int, tuple[np.ndarray, dict[int, int]]] = {}
        self.far = blocks.coupling < self.FAR_RESPONSE_MAX_COUPLING
        if self.far:
            self.tilt_basis, self.tilt = self._tilts(counts)

    def _near_pillars(self, counts: np.ndarray, n: int
                      ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per pillar, the nearest pillars (by centroid, from the blocks'
        `_interaction`) whose response to its change `respond` adds, as many
        as NEIGHBOURS and the pair budget allow; and its LOCAL nearest."""
        cy, cx = self.blocks._centroids
        budget = self.NEIGHBOUR_PAIRS_PER_ELEMENT * n * n
        near = []
        local = []  # for `_far_response`
        for p in range(counts.size):
            dist = np.hypot(cy - cy[p], cx - cx[p])
            dist[p] = np.inf
            order = np.argsort(dist)[: min(self.LOCAL, counts.size - 1)]
            local.append(order)
            order = order[: self.NEIGHBOURS]
            pairs = counts[p] * np.cumsum(counts[order])
            near.append(order[pairs <= budget])
        return near, local

    def _tilts(self, counts: np.ndarray) -> tuple[Any, Any]:
        """Each element's offset (y, x) from its pillar's centroid, and the
        basis of fields to second order over a pillar, shape (N, m, 5):
        y, x, y^2, y x, x^2 [length, length^2]; with each pillar's response
        to them, G_p basis (`_far_response`), in the stacks' namespace."""
        b = self.blocks
        cy, cx = b._centroids
        valid = np.arange(b.m)[None, :] < counts[:, None]
        dy, dx = (b._yy - cy[:, None]) * valid, (b._xx - cx[:, None]) * valid
        self._offsets_host = np.stack([dy, dx], axis=2)
        basis = b.backend.asarray(np.stack([dy, dx, dy * dy, dy * dx, dx * dx], axis=2))
        return basis, b.backend.xp.matmul(b.inv, basis)

    def refresh(self, p: Any, g: Any) -> None:
        """Pillars p's responses to the tilts (while `far`) after their block
        inverses became ``g``: one pillar (an integer, g of shape (m, m)) or
        several (an index array in the stacks' namespace, g (t, m, m))."""
        if self.far:
            be = self.blocks.backend
            be.put(self.tilt, p, g @ be.xp.take(self.tilt_basis, p, axis=0))

    def respond(self, touched: np.ndarray, live_before: np.ndarray, before: list) -> None:
        """The answer of the other pillars to a detachment, in the blocks'
        stacked stresses: the near neighbours' first-order responses, then
        (where on) the far field's warm start of every other pillar."""
        sources = self._neighbour_response(touched, live_before, before)
        if self.far:
            self._far_response(sources)

    def _neighbour_response(self, touched: np.ndarray, live_before: np.ndarray,
                            before: list) -> list[tuple]:
        """Add to the stacked stresses (the blocks' `_row`) the first-order
        response of each changed pillar's near neighbours: sigma_q -= G_q K_qp
        d sigma_p.

        ``live_before`` and ``before`` hold the touched pillars' attached
        slots and stresses before the detachment.  A warm start only: the
        global solve that follows corrects what it misses.  A soft pillar's
        cascade shifts load across its face with its total nearly fixed, a
        field that falls off fast, so the nearest pillars take most of the
        response, which CG's first iteration would otherwise spend an
        application finding (random 220 at kbar 1e-4: 24 % fewer).
        Coefficients come from host geometry; on a device they cross as
        small blocks, never as fields.

        Returns the changes whose field no pillar has answered yet, for
        `_far_response`: (pillar, slots, change on them, pillars that
        already answered, pillars to answer or None for all), each touched
        pillar's and each neighbour's.
        """
        b = self.blocks
        be = b.backend
        xp = be.xp
        skip = set(touched.tolist())
        sources = []
        for p, live, old in zip(touched, live_before, before):
            near = [q for q in self.neighbours[p] if q not in skip and b._remaining[q]]
            cols = np.flatnonzero(live)
            change = xp.take(b._row(p) - old, be.asarray(cols))
            sources.append((int(p), cols, change, [int(p)] + near, None))
            if not near:
                continue
            # All neighbours' coefficients in one gather from p's cached
            # block; each keeps its own product (a row slice: the same
            # numbers as a block of its own).
            live_rows = [np.flatnonzero(b._live[q]) for q in near]
            sizes = [rows.size for rows in live_rows]
            block, first_row = self._near_block(int(p))
            coefficients = block[np.ix_(np.concatenate(
                [first_row[q] + rows for q, rows in zip(near, live_rows)]), cols)]
            ends = np.cumsum(sizes)
            for q, rows, end, size in zip(near, live_rows, ends, sizes):
                u = xp.zeros(b.m, dtype=xp.float64)
                shift = be.asarray(coefficients[end - size:end]) @ change
                be.put(u, be.asarray(rows), shift)
                response = b.inv[q, :, :] @ u  # G_q: 0 off live
                b._set_row(q, b._row(q) - response)
                # second order: its field matters near it only
                sources.append((q, rows, -xp.take(response, be.asarray(rows)), [q],
                                self.local[q]))
        return sources

    def _near_block(self, p: int) -> tuple[np.ndarray, dict[int, int]]:
        """K_qp for all slots of p's neighbours q (rows, stacked in the order
        of `neighbours`) and of p (columns) [length / stress], and each q's
        first row; the last NEAR_BLOCKS_KEPT pillars' blocks are kept.
        Sliced to the live slots, the same numbers as the blocks'
        `_coefficients` (random 425 at kbar 3e-6, 512^2: 0.6 ms a round for
        the lookups)."""
        kept = self._near_blocks
        if p in kept:
            kept[p] = kept.pop(p)  # most recently used last
            return kept[p]
        b = self.blocks
        near = self.neighbours[p]
        slots = np.arange(b.m)
        block = b._coefficients(np.repeat(near, b.m), np.tile(slots, near.size), p, slots)
        kept[p] = block, {int(q): i * b.m for i, q in enumerate(near)}
        if len(kept) > self.NEAR_BLOCKS_KEPT:
            kept.pop(next(iter(kept)))
        return kept[p]

    def _far_response(self, sources: list[tuple]) -> None:
        """Add every pillar's response to the far field of ``sources`` (see
        `_neighbour_response`): sigma_f -= G_f phi_f, phi_f expanded about
        f's centroid to second order,

            G_f phi_f = phi z_f + grad phi . (G_f d_f) + 1/2 H : (G_f d_f d_f),

        from the vectors `_tilts` keeps per pillar (d_f: offsets from c_f).
        A change dsigma on pillar p of moments M0 = C sum dsigma and M1 = C
        sum dsigma (x - c_p), C = h^2 / (pi E*) (Boussinesq's point load),
        displaces the surface at R from c_p by M0 / R + M1 . R / R^3 to
        dipole order; phi, its gradient and Hessian follow in closed form
        (images included on a quadrant).  What is left out is of relative
        order (a / R)^2.  A soft pillar answers a uniform field with its
        spring alone, so its gradient and Hessian terms carry the answer.

        A warm start, not a bound: the next global solve corrects the rest.
        Work is O(N) per touched pillar plus `LOCAL` per neighbour, no
        application.
        """
        b = self.blocks
        be = b.backend
        xp = be.xp
        if not sources:
            return
        cy, cx = b._centroids
        scale = b._h ** 2 / (np.pi * b._e_star)
        sizes = np.array([slots.size for _, slots, _, _, _ in sources])
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        change = xp.concat([c for _, _, c, _, _ in sources]) if len(sources) > 1 else sources[0][2]
        offsets = np.concatenate([self._offsets_host[p, slots] for p, slots, _, _, _ in sources])
        weighted = be.to_host(xp.stack([change, change * be.asarray(offsets[:, 0]),
                                        change * be.asarray(offsets[:, 1])]))
        moments = scale * np.add.reduceat(weighted, starts, axis=1)  # (3, sources)
        # (source, target) pairs: a touched pillar's change reaches every
        # pillar, a neighbour's (second order) only its `local` ones.
        everyone = np.arange(cy.size)
        targets = [everyone if to is None else to for _, _, _, _, to in sources]
        which = np.repeat(np.arange(len(sources)), [t.size for t in targets])
        target = np.concatenate(targets)
        keep = np.ones(target.size, dtype=bool)
        first = np.concatenate([[0], np.cumsum([t.size for t in targets])[:-1]])
        for i, (_, _, _, done, to) in enumerate(sources):
            if to is None:  # targets are all pillars, in order
                keep[first[i] + np.asarray(done)] = False
            # a neighbour answered only itself, which its `local` list leaves out
        which, target = which[keep], target[keep]
        source = np.array([p for p, _, _, _, _ in sources])[which]
        # What G_f answers with phi z_f + g . (G_f d) + 1/2 H : (G_f d d).
        terms = field_terms(moments[:, which], source, target, (cy, cx), b._h, b._mirrored)
        corr = (be.asarray(terms[0])[:, None] * b._z
                + xp.matmul(self.tilt, be.asarray(terms[1:].T)[:, :, None])[:, :, 0])
        b._subtract_all(corr)
