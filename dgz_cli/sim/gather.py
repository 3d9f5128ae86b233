"""Batched state gather: per-slot MjData copies → the env's padded batch buffers, without a Python
loop over slots on the observation path.

Each slot's worker thread copies whole MjData arrays into its row of ``raw`` (one contiguous copy each,
overlapping the other thread's physics) and stashes its contacts; :meth:`BatchGather.assemble` then
picks what the observation needs for a range of rows with flat ``np.take`` indices and sums the contact
forces per node with one table lookup and one ``bincount``.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.sim.slot import Slot


class BatchGather:
    def __init__(self, slots: list[Slot], buf: dict[str, np.ndarray], tables: list[np.ndarray],
                 model_of: list[int]) -> None:
        """Per-slot copies of whole MjData arrays (written by the worker threads, one contiguous copy each)
        and flat index arrays that pick what the observation needs for the whole batch in one ``np.take``.
        ``buf`` rows of ``xpos`` / ``xmat``: the N node bodies (padded), then the object body, then the palm
        body; ``q`` (B, L) hand joints, ``wq`` (B, 6) wrist joints, ``qd`` (B, L + 6) hand joint then
        object velocities; padding points at an extra all-zero (``xmat``: identity) row / column."""
        self.slots, self.buf = slots, buf
        B, N, L = len(slots), buf["xpos"].shape[1] - 2, buf["q"].shape[1]
        self.N = N
        # contact (geom1, geom2) → node tables of all models, padded, for the batched contact forces
        g = max(len(t) for t in tables)
        self._pair_node = np.full((len(tables), g, g), -1, np.int16)
        for m, t in enumerate(tables):
            self._pair_node[m, :len(t), :len(t)] = t
        self._model_of = np.array(model_of)
        nb = max(s.model.nbody for s in self.slots) + 1  # + a padding body
        nq = max(s.model.nq for s in self.slots) + 1
        nv = max(s.model.nv for s in self.slots) + 1
        self.raw = dict(xpos=np.zeros((B, nb, 3)), xmat=np.zeros((B, nb, 9)), qpos=np.zeros((B, nq)),
                        qvel=np.zeros((B, nv)))
        self.raw["xmat"][:, nb - 1] = np.eye(3).reshape(9)
        self._take_body = np.full((B, N + 2), nb - 1)
        self._take_q = np.full((B, L), nq - 1)
        self._take_wq = np.zeros((B, 6), np.int64)
        self._take_qd = np.full((B, L + 6), nv - 1)
        for b, s in enumerate(slots):
            idx, n, l = s.idx, len(s.spec.nodes), s.n_joints
            self._take_body[b, :n] = idx.node_body
            self._take_body[b, N:] = idx.object_body, idx.palm_body
            self._take_q[b, :l] = idx.hand_qadr
            self._take_wq[b] = idx.wrist_qadr
            self._take_qd[b, :l] = idx.hand_dadr
            self._take_qd[b, L:] = np.arange(idx.object_dadr, idx.object_dadr + 6)
            s.bind(self.raw["xpos"][b], self.raw["xmat"][b], self.raw["qpos"][b], self.raw["qvel"][b],
                   self.buf["force"][b, :n], stash_contacts=True)
        self._take_body += np.arange(B)[:, None] * nb  # flat indices into the (B * rows, ...) raw arrays
        self._take_q += np.arange(B)[:, None] * nq
        self._take_wq += np.arange(B)[:, None] * nq
        self._take_qd += np.arange(B)[:, None] * nv

    def assemble(self, rows: slice) -> None:
        """Fill ``buf`` rows (a slice with start and stop) from what the slots' ``gather`` left: poses and
        joints with five ``np.take`` over the rows, contact forces with one lookup and one ``bincount``
        over all their contacts."""
        self._contact_forces(rows)
        raw, buf = self.raw, self.buf
        np.take(raw["xpos"].reshape(-1, 3), self._take_body[rows], axis=0, out=buf["xpos"][rows])
        np.take(raw["xmat"].reshape(-1, 9), self._take_body[rows], axis=0, out=buf["xmat"][rows])
        qpos = raw["qpos"].reshape(-1)
        np.take(qpos, self._take_q[rows], out=buf["q"][rows])
        np.take(qpos, self._take_wq[rows], out=buf["wq"][rows])
        np.take(raw["qvel"].reshape(-1), self._take_qd[rows], out=buf["qd"][rows])

    def _contact_forces(self, rows: slice) -> None:
        """``buf["force"]`` rows: per node, the summed normal force (the first row of an elliptic cone, N) of
        its hand–object contacts, from the contacts the slots stashed, for all of them at once: one table
        lookup and one ``bincount``, which adds in contact order from 0 like a per-contact loop. Slots that
        do not stash (pyramidal cones) wrote their own rows in ``gather``."""
        lo, hi, N = rows.start, rows.stop, self.N
        slots = self.slots[lo:hi]
        stash = [(b, s.con) for b, s in zip(range(lo, hi), slots) if s.stash_contacts and s.con is not None]
        out = np.zeros((hi - lo) * N)
        if stash:
            count = [len(c[1]) for _, c in stash]
            slot = np.repeat([b for b, _ in stash], count)
            geom = np.concatenate([c[0] for _, c in stash])
            adr = np.concatenate([c[1] for _, c in stash])
            efc = [c[2] for _, c in stash]
            base = np.repeat(np.cumsum([0] + [len(e) for e in efc[:-1]]), count)  # each slot's offset in efc
            node = self._pair_node[self._model_of[slot], geom[:, 0], geom[:, 1]]
            sel = (node >= 0) & (adr >= 0)
            if sel.any():
                out = np.bincount((slot[sel] - lo) * N + node[sel], weights=np.concatenate(efc)[adr[sel] + base[sel]],
                                  minlength=(hi - lo) * N)
        out = out.reshape(hi - lo, N)
        if all(s.stash_contacts for s in slots):
            self.buf["force"][rows] = out
        else:
            mine = np.array([s.stash_contacts for s in slots])
            self.buf["force"][lo:hi][mine] = out[mine]
