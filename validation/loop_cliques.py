"""Maximum clique of a consistency graph (for pairwise consistency, PCM).

Branch and bound with a greedy colouring bound (Tomita and Seki's MCQ): the
vertices of a branch are coloured greedily; a clique can take at most one
vertex per colour, so a branch whose colours cannot beat the best clique is
cut. Vertex sets are Python integers used as bit sets. ``max_steps`` bounds
the work; past it the best clique found so far is returned (a greedy clique
is found first, so there always is one). Deterministic: ties go to the
lower vertex index.
"""

from __future__ import annotations

import numpy as np


def _bits(mask: int) -> list[int]:
    out = []
    while mask:
        low = mask & -mask
        out.append(low.bit_length() - 1)
        mask ^= low
    return out


def _colour(candidates: int, neighbours: list[int]) -> list[tuple[int, int]]:
    """Greedy colouring of ``candidates``: (vertex, colour) with colours
    non-decreasing, for the MCQ bound."""
    order: list[tuple[int, int]] = []
    uncoloured = candidates
    colour = 0
    while uncoloured:
        colour += 1
        available = uncoloured
        while available:
            v = (available & -available).bit_length() - 1
            available &= ~neighbours[v] & ~(1 << v)
            uncoloured &= ~(1 << v)
            order.append((v, colour))
    return order


def greedy_clique(adjacency: np.ndarray) -> list[int]:
    """A maximal clique grown from the vertex of highest degree, adding
    the candidate with the most neighbours among the remaining candidates."""
    n = len(adjacency)
    if n == 0:
        return []
    adj = np.asarray(adjacency, dtype=bool)
    degree = adj.sum(axis=1)
    clique = [int(np.argmax(degree))]
    cand = adj[clique[0]].copy()
    while cand.any():
        idx = np.flatnonzero(cand)
        inner = adj[np.ix_(idx, idx)].sum(axis=1)
        v = int(idx[np.argmax(inner)])
        clique.append(v)
        cand &= adj[v]
        cand[v] = False
    return sorted(clique)


def maximum_clique(adjacency: np.ndarray, max_steps: int = 200_000) -> tuple[list[int], bool]:
    """Vertices of a maximum clique of the symmetric boolean ``adjacency``
    (n, n) (the diagonal is ignored), and whether it is proven maximum
    (False when ``max_steps`` ran out)."""
    n = len(adjacency)
    if n == 0:
        return [], True
    adj = np.asarray(adjacency, dtype=bool).copy()
    np.fill_diagonal(adj, False)
    # Row i as an integer whose bit v is adj[i, v].
    packed = np.packbits(adj, axis=1, bitorder="little")
    neighbours = [int.from_bytes(row.tobytes(), "little") for row in packed]
    best = greedy_clique(adj)
    best_size = len(best)
    steps = 0
    exhausted = False

    def expand(clique: list[int], candidates: int) -> None:
        nonlocal best, best_size, steps, exhausted
        order = _colour(candidates, neighbours)
        for v, colour in reversed(order):
            steps += 1
            if steps > max_steps:
                exhausted = True
                return
            if len(clique) + colour <= best_size:
                return
            new_candidates = candidates & neighbours[v]
            clique.append(v)
            if new_candidates:
                expand(clique, new_candidates)
                if exhausted:
                    clique.pop()
                    return
            elif len(clique) > best_size:
                best, best_size = sorted(clique), len(clique)
            clique.pop()
            candidates &= ~(1 << v)

    expand([], (1 << n) - 1)
    return best, not exhausted
