"""Directed communication graphs (paper Section IV, docs/model.md §4).

Convention of the paper: if vessel ``i`` transmits to vessel ``j``, the graph
has the edge ``(j, i)``, i.e. edges point *against* the flow of information.
``A_j = {i : (j, i) ∈ E}`` is the set of vessels whose data vessel ``j``
receives. Node ``k`` is *globally reachable* if it can be reached from every
node by following edges; Proposition 2 needs at least one such node.

People usually think in terms of links "i transmits to j"; use
``CommGraph.from_links`` for that, ``CommGraph.from_edges`` for the
paper's convention, or ``CommGraph.from_adjacency`` for a matrix with
``A[j, i] = 1`` iff ``i ∈ A_j``.

Presets (``make_graph``), for any ``n ≥ 2`` unless noted; one-way links
unless the name ends in ``_bidirectional``:

=========================  =====================================================
``paper``                  n = 3: 1 → 0, 1 → 2, 0 → 2 (docs/model.md §5; vessel 1 leads)
``chain``                  0 → 1 → 2 → … → n−1 (vessel 0 leads)
``ring``                   0 → 1 → … → n−1 → 0 (every node globally reachable)
``leader_follower``        0 → every other vessel (alias ``star``)
``complete``               every vessel to every other (two-way by nature)
``random``                 seeded random digraph that contains a spanning tree
                           (a random tree rooted at a random leader, plus each
                           remaining link with probability ``p``)
=========================  =====================================================
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["GRAPH_PRESETS", "CommGraph", "GraphError", "make_graph", "spread_bound"]


class GraphError(ValueError):
    """A malformed communication graph or an unknown preset."""


def _as_pairs(pairs: Iterable[Sequence[int]], n: int, what: str) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for pair in pairs:
        try:
            a, b = pair
        except (TypeError, ValueError):
            raise GraphError(f"each {what} must be a pair of vessel indices, got {pair!r}") from None
        for node in (a, b):
            if isinstance(node, bool) or not isinstance(node, (int, np.integer)):
                raise GraphError(f"{what} {tuple(pair)!r}: vessel indices must be integers, got {node!r}")
            if not 0 <= int(node) < n:
                raise GraphError(f"{what} {tuple(pair)!r}: vessel index {node} is out of range [0, {n - 1}]")
        if int(a) == int(b):
            raise GraphError(f"{what} {tuple(pair)!r} is a self-loop; a vessel does not transmit to itself")
        out.append((int(a), int(b)))
    return out


@dataclass(frozen=True, eq=False)
class CommGraph:
    """A directed communication graph over ``n`` vessels (paper convention).

    Build it with one of the constructors; the instance is immutable.

    Attributes:
        adjacency: ``(n, n)`` boolean array, ``adjacency[j, i]`` iff vessel ``j``
            receives from vessel ``i`` (``i ∈ A_j``, edge ``(j, i)``).
        name: a label (the preset name or ``"custom"``).
    """

    adjacency: np.ndarray
    name: str = "custom"

    def __post_init__(self) -> None:
        adj = np.asarray(self.adjacency)
        if adj.ndim != 2 or adj.shape[0] != adj.shape[1]:
            raise GraphError(f"adjacency must be a square (n, n) matrix, got shape {adj.shape}")
        if adj.shape[0] < 2:
            raise GraphError(f"a formation needs at least 2 vessels, got n = {adj.shape[0]}")
        if not np.all(np.isin(adj, (0, 1))):
            bad = adj[~np.isin(adj, (0, 1))].ravel()[0]
            raise GraphError(f"adjacency entries must be 0 or 1 (or booleans), found {bad!r}")
        adj = adj.astype(bool)
        if np.any(np.diag(adj)):
            node = int(np.flatnonzero(np.diag(adj))[0])
            raise GraphError(f"adjacency[{node}, {node}] = 1 is a self-loop; the diagonal must be zero")
        adj = adj.copy()
        adj.setflags(write=False)
        object.__setattr__(self, "adjacency", adj)

    # ---------------------------------------------------------------- builders
    @classmethod
    def from_edges(cls, n: int, edges: Iterable[Sequence[int]], name: str = "custom") -> CommGraph:
        """From edges ``(j, i)`` in the paper's convention: ``i`` transmits to ``j``."""
        n = _check_n(n)
        return cls.from_links(n, [(i, j) for j, i in _as_pairs(edges, n, "edge")], name)

    @classmethod
    def from_links(cls, n: int, links: Iterable[Sequence[int]], name: str = "custom") -> CommGraph:
        """From links ``(i, j)`` meaning "vessel ``i`` transmits to vessel ``j``"."""
        n = _check_n(n)
        adj = np.zeros((n, n), dtype=bool)
        for i, j in _as_pairs(links, n, "link"):
            adj[j, i] = True
        return cls(adj, name)

    @classmethod
    def from_adjacency(cls, matrix: Sequence[Sequence[float]] | np.ndarray, name: str = "custom") -> CommGraph:
        """From a 0/1 matrix with ``matrix[j, i] = 1`` iff ``i`` transmits to ``j``."""
        try:
            arr = np.asarray(matrix)
        except ValueError:
            raise GraphError("adjacency must be a rectangular (n, n) matrix (ragged rows given)") from None
        if arr.dtype == object:
            raise GraphError("adjacency must be a rectangular (n, n) numeric matrix")
        return cls(arr, name)

    # ---------------------------------------------------------------- queries
    @property
    def n(self) -> int:
        """Number of vessels."""
        return int(self.adjacency.shape[0])

    @property
    def edges(self) -> list[tuple[int, int]]:
        """Edges ``(j, i)`` in the paper's convention, sorted."""
        return [(int(j), int(i)) for j, i in zip(*np.nonzero(self.adjacency), strict=True)]

    @property
    def links(self) -> list[tuple[int, int]]:
        """Links ``(i, j)``: vessel ``i`` transmits to vessel ``j``, sorted by transmitter."""
        return sorted((i, j) for j, i in self.edges)

    def neighbors(self, j: int) -> list[int]:
        """``A_j``: the vessels whose data vessel ``j`` receives."""
        return [int(i) for i in np.flatnonzero(self.adjacency[j])]

    @property
    def laplacian(self) -> np.ndarray:
        """Graph Laplacian ``L = diag(|A_j|) − A`` (rows sum to zero)."""
        adj = self.adjacency.astype(float)
        return np.diag(adj.sum(axis=1)) - adj

    def reachable_from(self, j: int) -> set[int]:
        """Nodes reachable from ``j`` along edges (including ``j``)."""
        seen = {int(j)}
        stack = [int(j)]
        while stack:
            k = stack.pop()
            for i in np.flatnonzero(self.adjacency[k]):
                if int(i) not in seen:
                    seen.add(int(i))
                    stack.append(int(i))
        return seen

    def globally_reachable_nodes(self) -> list[int]:
        """Nodes reachable from every node (Proposition 2 needs at least one)."""
        common = set(range(self.n))
        for j in range(self.n):
            common &= self.reachable_from(j)
        return sorted(common)

    @property
    def has_globally_reachable_node(self) -> bool:
        """Whether consensus is guaranteed by Proposition 2."""
        return bool(self.globally_reachable_nodes())

    @property
    def is_bidirectional(self) -> bool:
        """Whether every link is two-way."""
        return bool(np.array_equal(self.adjacency, self.adjacency.T))

    def bidirectional(self) -> CommGraph:
        """The graph with every link made two-way."""
        return CommGraph(self.adjacency | self.adjacency.T, f"{self.name}_bidirectional")

    def require_globally_reachable(self) -> None:
        """Raise ``GraphError`` if no node is globally reachable."""
        if not self.has_globally_reachable_node:
            raise GraphError(
                f"communication graph {self.name!r} (links i→j: {self.links}) has no globally "
                "reachable node, so Proposition 2 does not guarantee consensus; pass "
                "allow_unreachable=True to use it anyway"
            )

    def __eq__(self, other: object) -> bool:
        return isinstance(other, CommGraph) and np.array_equal(self.adjacency, other.adjacency)

    def __hash__(self) -> int:
        return hash(self.adjacency.tobytes())

    def __repr__(self) -> str:
        return f"CommGraph(name={self.name!r}, n={self.n}, links={self.links})"


def _check_n(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise GraphError(f"a formation needs an integer number of vessels n ≥ 2, got {n!r}")
    return int(n)


def _random_graph(n: int, seed: int | None, p: float) -> CommGraph:
    if not 0.0 <= p <= 1.0:
        raise GraphError(f"random graph link probability p must be in [0, 1], got {p!r}")
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)  # order[0] is the root (leader)
    adj = np.zeros((n, n), dtype=bool)
    for pos in range(1, n):
        parent = order[rng.integers(0, pos)]  # an earlier node transmits to this one
        adj[order[pos], parent] = True
    extra = rng.random((n, n)) < p
    np.fill_diagonal(extra, False)
    return CommGraph(adj | extra, "random")


#: Preset names accepted by ``make_graph``.
GRAPH_PRESETS = (
    "paper",
    "chain",
    "chain_bidirectional",
    "ring",
    "ring_bidirectional",
    "leader_follower",
    "leader_follower_bidirectional",
    "star",
    "star_bidirectional",
    "complete",
    "random",
)


def make_graph(name: str, n: int, seed: int | None = None, p: float = 0.2) -> CommGraph:
    """Build a preset graph (see the module docstring).

    Args:
        name: one of ``GRAPH_PRESETS``.
        n: number of vessels (``paper`` needs 3).
        seed: seed of the ``random`` preset (ignored by the others).
        p: extra-link probability of the ``random`` preset.

    Raises:
        GraphError: for an unknown name or an ``n`` the preset does not support.
    """
    n = _check_n(n)
    if not isinstance(name, str) or name not in GRAPH_PRESETS:
        raise GraphError(f"unknown topology preset {name!r}; known presets: {list(GRAPH_PRESETS)}")
    base = name.removesuffix("_bidirectional")
    if base == "paper":
        if n != 3:
            raise GraphError(f"topology 'paper' is defined for 3 vessels, got n_vessels = {n}")
        graph = CommGraph.from_links(3, [(1, 0), (1, 2), (0, 2)], "paper")
    elif base == "chain":
        graph = CommGraph.from_links(n, [(k, k + 1) for k in range(n - 1)], "chain")
    elif base == "ring":
        graph = CommGraph.from_links(n, [(k, (k + 1) % n) for k in range(n)], "ring")
    elif base in ("leader_follower", "star"):
        graph = CommGraph.from_links(n, [(0, k) for k in range(1, n)], base)
    elif base == "complete":
        graph = CommGraph(~np.eye(n, dtype=bool), "complete")
    else:
        graph = _random_graph(n, seed, p)
    return graph.bidirectional() if name.endswith("_bidirectional") else graph


def spread_bound(graph: CommGraph, delta: float) -> float:
    """The largest along-path spread ``max θ − min θ`` [m] at which the coordination law (20) can settle when
    each vessel knows its neighbours' ``θ_i`` only within ``δ`` (event-triggered broadcasting, ideal links).

    Derived for a graph led by one vessel ``r`` that listens to none (``A_r = ∅``, as in ``paper`` and
    ``chain``). At rest every vessel runs at the leader's speed ``u_d``, so the law's sum over what vessel
    ``j`` believes, ``Σ_{i∈A_j} (θ_j − θ̂_i)``, is 0; with ``θ̂_i = θ_i + ε_i``, ``|ε_i| < δ``, the true
    offsets from the leader ``θ̃ = θ − θ_r`` solve ``L̃ θ̃ = ε̄`` with ``L̃`` the Laplacian without the
    leader's row and column and ``|ε̄_j| ≤ |A_j|·δ``. Hence ``|θ̃_k| ≤ b_k = δ·Σ_j |L̃⁻¹|_{kj}·|A_j|`` and
    the spread is at most the sum of the two largest ``b_k`` (with ``b_r = 0``). For ``paper``:
    ``b = (δ, 1.5·δ)``, a bound of ``2.5·δ``.

    Raises:
        GraphError: the graph has no single vessel that listens to none.
    """
    adjacency = graph.adjacency.astype(bool)
    leaders = [j for j in range(graph.n) if not adjacency[j].any()]
    if len(leaders) != 1:
        raise GraphError(
            f"spread_bound needs one vessel that listens to none (a leader), graph {graph.name!r} has {len(leaders)}"
        )
    others = [j for j in range(graph.n) if j != leaders[0]]
    grounded = graph.laplacian[np.ix_(others, others)]
    per_vessel = np.abs(np.linalg.inv(grounded)) @ adjacency[others].sum(axis=1) * delta
    largest = np.sort(np.append(per_vessel, 0.0))[::-1]
    return float(largest[0] + largest[1])
