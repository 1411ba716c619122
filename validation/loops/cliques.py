"""Maximum clique of a consistency graph (for pairwise consistency, PCM).

A greedy clique first; then every vertex with fewer neighbours than that
clique has is removed, repeatedly (it cannot be in a larger clique: a
k-core pruning, as in Pattabiraman et al.'s fast maximum clique). On what is
left, branch and bound with a greedy colouring bound (Tomita and Seki's
MCQ): the vertices of a branch are coloured greedily; a clique can take at
most one vertex per colour, so a branch whose colours cannot beat the best
clique is cut. Vertex sets are Python integers used as bit sets. ``max_steps`` bounds
the work (vertices coloured and tried); past it the best clique found so far
is returned (a greedy clique is found first, so there always is one). Deterministic: ties go to the
lower vertex index.
"""

from __future__ import annotations

import numpy as np


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
    cand[clique[0]] = False
    inner = adj[:, cand].sum(axis=1)  # neighbours among the candidates
    while cand.any():
        idx = np.flatnonzero(cand)
        v = int(idx[np.argmax(inner[idx])])
        clique.append(v)
        removed = cand & ~adj[v]
        removed[v] = True
        cand &= ~removed
        if removed.any():
            inner -= adj[:, removed].sum(axis=1)
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
    best = greedy_clique(adj)
    best_size = len(best)
    # Only vertices with at least best_size neighbours can be in a larger clique.
    alive = np.ones(n, dtype=bool)
    while True:
        degree = adj[:, alive].sum(axis=1)
        drop = alive & (degree < best_size)
        if not drop.any():
            break
        alive &= ~drop
    keep = np.flatnonzero(alive)
    if len(keep) == 0:
        return best, True
    sub = adj[np.ix_(keep, keep)]
    # Row i as an integer whose bit v is sub[i, v].
    packed = np.packbits(sub, axis=1, bitorder="little")
    neighbours = [int.from_bytes(row.tobytes(), "little") for row in packed]
    found: list[int] = []
    steps = 0
    exhausted = False

    def expand(clique: list[int], candidates: int) -> None:
        nonlocal best_size, steps, exhausted
        order = _colour(candidates, neighbours)
        steps += len(order)
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
                found[:], best_size = clique, len(clique)
            clique.pop()
            candidates &= ~(1 << v)

    expand([], (1 << len(keep)) - 1)
    if found:
        best = sorted(int(keep[v]) for v in found)
    return best, not exhausted
