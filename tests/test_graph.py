"""Tests of :mod:`marine_formation_env.graph` (paper Section IV, docs/model.md §4).

Convention: vessel i transmits to vessel j ⇔ edge (j, i) ⇔ A[j, i] = 1 ⇔ i ∈ A_j.
Node k is globally reachable if it can be reached from every node along edges.

Independent truths: hand-worked answers for small graphs, and the transitive
closure computed by ``scipy.sparse.csgraph.shortest_path`` (``M[a, b]`` is an
arc a → b there, which matches edge (j, i) stored as A[j, i]).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import shortest_path

from marine_formation_env.graph import GRAPH_PRESETS, CommGraph, GraphError, make_graph

pytestmark = pytest.mark.backend_independent


def closure(adj: np.ndarray) -> np.ndarray:
    """reach[a, b] iff b is reachable from a along edges (a itself included)."""
    dist = shortest_path(np.asarray(adj, dtype=float), directed=True, unweighted=True)
    return np.isfinite(dist)


def independent_globally_reachable(adj: np.ndarray) -> list[int]:
    reach = closure(adj)
    return [int(k) for k in np.flatnonzero(reach.all(axis=0))]


# --------------------------------------------------------- hand-made answers
def test_paper_preset() -> None:
    g = make_graph("paper", 3)
    # docs/model.md §5: links 1 → 0, 1 → 2, 0 → 2, i.e. edges (0,1), (2,1), (2,0)
    assert sorted(g.edges) == [(0, 1), (2, 0), (2, 1)]
    assert g.links == [(0, 2), (1, 0), (1, 2)]
    assert g.neighbors(0) == [1] and g.neighbors(1) == [] and g.neighbors(2) == [0, 1]
    assert g.globally_reachable_nodes() == [1]
    assert g.reachable_from(2) == {0, 1, 2}
    assert g.reachable_from(0) == {0, 1}
    assert g.reachable_from(1) == {1}
    assert g.has_globally_reachable_node
    g.require_globally_reachable()  # does not raise
    assert not g.is_bidirectional


@pytest.mark.parametrize(
    ("n", "links", "expected"),
    [
        (4, [(0, 1), (1, 2), (2, 3)], [0]),  # chain: leader 0
        (4, [(0, 1), (1, 2), (2, 3), (3, 0)], [0, 1, 2, 3]),  # ring
        (4, [(0, 1), (1, 0), (2, 3), (3, 2)], []),  # two disconnected pairs
        (5, [(0, 1), (0, 2), (0, 3), (0, 4)], [0]),  # star, one-way from 0
        (3, [(0, 1), (2, 1)], []),  # two leaders: nobody hears both
        # 2 → 1 and 0 ↔ 1; edges (1,2), (0,1), (1,0): from 0 and 1 all are reachable,
        # from 2 (which receives nothing) only 2 itself, so 2 is the only leader
        (3, [(2, 1), (1, 0), (0, 1)], [2]),
        (3, [(2, 1), (1, 0), (0, 1), (1, 2)], [0, 1, 2]),
        (2, [], []),  # no links at all
    ],
)
def test_globally_reachable_hand_made(n: int, links: list[tuple[int, int]], expected: list[int]) -> None:
    g = CommGraph.from_links(n, links)
    assert g.globally_reachable_nodes() == expected
    assert g.has_globally_reachable_node == bool(expected)
    assert g.globally_reachable_nodes() == independent_globally_reachable(g.adjacency)


def test_require_globally_reachable_raises_for_disconnected_pairs() -> None:
    g = CommGraph.from_links(4, [(0, 1), (1, 0), (2, 3), (3, 2)])
    with pytest.raises(GraphError, match="no globally reachable node"):
        g.require_globally_reachable()


def test_require_globally_reachable_message_names_links() -> None:
    g = CommGraph.from_links(3, [(0, 1), (2, 1)], name="two_leaders")
    with pytest.raises(GraphError, match=r"'two_leaders'.*\(0, 1\), \(2, 1\)"):
        g.require_globally_reachable()


# ------------------------------------------------------- constructor agreement
@settings(max_examples=150, deadline=None)
@given(
    st.integers(2, 7).flatmap(
        lambda n: st.tuples(
            st.just(n), st.lists(st.lists(st.booleans(), min_size=n, max_size=n), min_size=n, max_size=n)
        )
    )
)
def test_constructors_agree_and_reachability_matches_closure(data: tuple[int, list[list[bool]]]) -> None:
    n, rows = data
    adj = np.array(rows, dtype=bool)
    np.fill_diagonal(adj, False)
    links = [(i, j) for j in range(n) for i in range(n) if adj[j, i]]  # i transmits to j
    edges = [(j, i) for (i, j) in links]
    g_links = CommGraph.from_links(n, links)
    g_edges = CommGraph.from_edges(n, edges)
    g_adj = CommGraph.from_adjacency(adj.astype(int))
    assert g_links == g_edges == g_adj
    np.testing.assert_array_equal(g_links.adjacency, adj)
    assert g_links.links == sorted(links)
    assert sorted(g_links.edges) == sorted(edges)
    for j in range(n):
        assert g_links.neighbors(j) == sorted(i for (i, jj) in links if jj == j)  # A_j
    reach = closure(adj)
    for j in range(n):
        assert g_links.reachable_from(j) == {int(k) for k in np.flatnonzero(reach[j])}
    assert g_links.globally_reachable_nodes() == independent_globally_reachable(adj)
    # Laplacian: rows sum to 0, diagonal = |A_j|, off-diagonal −1 exactly on A_j
    lap = g_links.laplacian
    np.testing.assert_allclose(lap.sum(axis=1), 0.0, atol=0)
    for j in range(n):
        assert lap[j, j] == len([1 for (_, jj) in links if jj == j])
        for i in range(n):
            if i != j:
                assert lap[j, i] == (-1.0 if (i, j) in links else 0.0)
    # bidirectional: symmetric, contains the original, and nothing else
    b = g_links.bidirectional()
    assert b.is_bidirectional
    np.testing.assert_array_equal(b.adjacency, adj | adj.T)


def test_laplacian_of_paper_graph() -> None:
    # |A_0| = 1 (from 1), |A_1| = 0, |A_2| = 2 (from 0 and 1)
    expected = np.array([[1, -1, 0], [0, 0, 0], [-1, -1, 2]], dtype=float)
    np.testing.assert_array_equal(make_graph("paper", 3).laplacian, expected)


def test_adjacency_is_read_only_and_copied() -> None:
    m = np.array([[0, 1], [0, 0]])
    g = CommGraph.from_adjacency(m)
    m[1, 0] = 1  # mutating the input does not change the graph
    assert g.links == [(1, 0)]
    with pytest.raises(ValueError):
        g.adjacency[0, 1] = False


# --------------------------------------------------------------------- presets
@pytest.mark.parametrize("name", [p for p in GRAPH_PRESETS if p != "paper"])
@pytest.mark.parametrize("n", range(2, 9))
def test_every_preset_has_a_globally_reachable_node(name: str, n: int) -> None:
    g = make_graph(name, n, seed=n)
    assert g.n == n
    assert not np.any(np.diag(g.adjacency))
    assert independent_globally_reachable(g.adjacency), (name, n, g.links)
    assert g.has_globally_reachable_node
    if name.endswith("_bidirectional") or name == "complete":
        assert g.is_bidirectional
        np.testing.assert_array_equal(g.adjacency, g.adjacency.T)
        assert g.globally_reachable_nodes() == list(range(n))


@pytest.mark.parametrize("n", range(2, 9))
def test_preset_structures(n: int) -> None:
    assert make_graph("chain", n).links == [(k, k + 1) for k in range(n - 1)]
    assert make_graph("chain", n).globally_reachable_nodes() == [0]
    assert sorted(make_graph("ring", n).links) == sorted({(k, (k + 1) % n) for k in range(n)})
    assert make_graph("ring", n).globally_reachable_nodes() == list(range(n))
    for star in ("leader_follower", "star"):
        g = make_graph(star, n)
        assert g.links == [(0, k) for k in range(1, n)]
        assert g.globally_reachable_nodes() == [0]
    c = make_graph("complete", n)
    assert len(c.links) == n * (n - 1)
    for base in ("chain", "ring", "leader_follower", "star"):
        b = make_graph(f"{base}_bidirectional", n)
        a = make_graph(base, n).adjacency
        np.testing.assert_array_equal(b.adjacency, a | a.T)


def test_random_preset_always_contains_a_spanning_tree() -> None:
    for n in range(2, 11):
        for seed in range(51):
            g = make_graph("random", n, seed=seed)
            assert g.n == n
            assert not np.any(np.diag(g.adjacency))
            assert independent_globally_reachable(g.adjacency), (n, seed, g.links)


def test_random_preset_without_extra_links_is_a_rooted_tree() -> None:
    for n in range(2, 11):
        for seed in range(20):
            g = make_graph("random", n, seed=seed, p=0.0)
            in_degree = g.adjacency.sum(axis=1)  # |A_j|
            assert sorted(in_degree.tolist()) == [0] + [1] * (n - 1)
            root = int(np.flatnonzero(in_degree == 0)[0])
            assert independent_globally_reachable(g.adjacency) == [root]


def test_random_preset_is_reproducible_and_varies_with_seed() -> None:
    for n in (3, 6, 10):
        for seed in range(10):
            assert make_graph("random", n, seed=seed) == make_graph("random", n, seed=seed)
    distinct = {make_graph("random", 6, seed=seed).adjacency.tobytes() for seed in range(51)}
    assert len(distinct) > 10


def test_random_preset_full_probability_is_complete() -> None:
    g = make_graph("random", 5, seed=3, p=1.0)
    np.testing.assert_array_equal(g.adjacency, ~np.eye(5, dtype=bool))


# ---------------------------------------------------------------------- errors
def test_self_loop_link_rejected() -> None:
    with pytest.raises(GraphError, match=r"\(1, 1\) is a self-loop"):
        CommGraph.from_links(3, [(0, 1), (1, 1)])


def test_self_loop_edge_rejected() -> None:
    with pytest.raises(GraphError, match=r"\(2, 2\) is a self-loop"):
        CommGraph.from_edges(3, [(2, 2)])


def test_self_loop_in_adjacency_rejected() -> None:
    with pytest.raises(GraphError, match=r"adjacency\[1, 1\]"):
        CommGraph.from_adjacency([[0, 1, 0], [0, 1, 0], [0, 0, 0]])


@pytest.mark.parametrize("pair", [(0, 3), (3, 0), (0, 17)])
def test_out_of_range_index_rejected(pair: tuple[int, int]) -> None:
    bad = max(pair)
    with pytest.raises(GraphError, match=rf"vessel index {bad} is out of range \[0, 2\]"):
        CommGraph.from_links(3, [pair])
    with pytest.raises(GraphError, match=rf"vessel index {bad} is out of range"):
        CommGraph.from_edges(3, [pair])


def test_negative_index_rejected() -> None:
    with pytest.raises(GraphError, match=r"vessel index -1 is out of range"):
        CommGraph.from_links(3, [(-1, 0)])


def test_non_integer_index_rejected() -> None:
    with pytest.raises(GraphError, match=r"1\.5"):
        CommGraph.from_links(3, [(0, 1.5)])


def test_non_pair_rejected() -> None:
    with pytest.raises(GraphError, match=r"\(0, 1, 2\)"):
        CommGraph.from_links(3, [(0, 1, 2)])


def test_non_square_adjacency_rejected() -> None:
    with pytest.raises(GraphError, match=r"\(2, 3\)"):
        CommGraph.from_adjacency([[0, 1, 0], [1, 0, 0]])


def test_one_dimensional_adjacency_rejected() -> None:
    with pytest.raises(GraphError, match=r"\(3,\)"):
        CommGraph.from_adjacency([0, 1, 0])


def test_ragged_adjacency_rejected() -> None:
    with pytest.raises(GraphError, match=r"ragged|rectangular"):
        CommGraph.from_adjacency([[0, 1], [1]])


@pytest.mark.parametrize(("value", "text"), [(2, "2"), (0.5, "0.5"), (-1, "-1")])
def test_non_binary_adjacency_rejected(value: float, text: str) -> None:
    with pytest.raises(GraphError, match=rf"0 or 1.*{text}"):
        CommGraph.from_adjacency([[0, value], [1, 0]])


def test_nan_adjacency_rejected() -> None:
    with pytest.raises(GraphError, match="nan"):
        CommGraph.from_adjacency([[0.0, float("nan")], [1.0, 0.0]])


@pytest.mark.parametrize("n", [1, 0, -3])
def test_too_few_vessels_rejected(n: int) -> None:
    with pytest.raises(GraphError, match=rf"got {n}\b"):
        make_graph("chain", n)
    with pytest.raises(GraphError, match=rf"got {n}\b"):
        CommGraph.from_links(n, [])


def test_single_vessel_adjacency_rejected() -> None:
    with pytest.raises(GraphError, match="n = 1"):
        CommGraph.from_adjacency([[0]])


@pytest.mark.parametrize("n", [2.0, True, "3"])
def test_non_integer_n_rejected(n: object) -> None:
    with pytest.raises(GraphError, match=repr(n).replace(".", r"\.")):
        make_graph("chain", n)  # type: ignore[arg-type]


def test_unknown_preset_rejected() -> None:
    with pytest.raises(GraphError, match=r"'nope'.*chain"):
        make_graph("nope", 3)


@pytest.mark.parametrize("n", [2, 4, 7])
def test_paper_preset_needs_three_vessels(n: int) -> None:
    with pytest.raises(GraphError, match=rf"'paper'.*n_vessels = {n}"):
        make_graph("paper", n)


@pytest.mark.parametrize("p", [-0.1, 1.5])
def test_random_preset_probability_range(p: float) -> None:
    with pytest.raises(GraphError, match=str(p)):
        make_graph("random", 4, seed=0, p=p)


def test_graph_error_is_value_error() -> None:
    assert issubclass(GraphError, ValueError)
