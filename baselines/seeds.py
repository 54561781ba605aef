"""Seed ranges: which episodes report results and which serve development.

Every tool that evaluates a policy draws its episode seeds from here, so that
one policy evaluated by two tools on ``n`` episodes is evaluated on the same
episodes.

* **Evaluation** seeds ``EVALUATION_SEED + k`` (``k = 0, 1, …``): the numbers
  that are reported (results tables, a run folder's ``evaluation.json``, a
  pretrained policy's header, ``python -m baselines.evaluate``'s default).
* **Development** seeds ``DEVELOPMENT_SEED + k``: evaluations *during*
  training (learning curves, keeping the best model) and tuning. They never
  overlap the evaluation seeds, so selecting a model on them does not select
  it on the episodes it is reported on.
* **Benchmark** seeds ``BENCHMARK_SEED + k``: reserved for the benchmark's
  evaluations (``docs/benchmark.md``) and its generalization track. No
  tuning, probe or development run uses them: the evaluation seeds above
  served the tuned rows' recipes while they were being chosen, these did not.

Training seeds (``--seed``) seed the learner and its environments; an
environment reset with seed ``s`` draws its initial state from ``s``.
"""

from __future__ import annotations

__all__ = [
    "BENCHMARK_SEED",
    "DEVELOPMENT_SEED",
    "EVALUATION_SEED",
    "benchmark_seeds",
    "development_seeds",
    "evaluation_seeds",
]

#: First seed of the evaluation range.
EVALUATION_SEED = 10_000
#: First seed of the development range (disjoint from the evaluation range for any practical episode count).
DEVELOPMENT_SEED = 1_000_000
#: First seed of the benchmark's reserved range.
BENCHMARK_SEED = 500_000


def _seeds(first: int, episodes: int) -> list[int]:
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    return [first + k for k in range(episodes)]


def evaluation_seeds(episodes: int) -> list[int]:
    """The seeds of ``episodes`` reported evaluation episodes: ``EVALUATION_SEED, EVALUATION_SEED + 1, …``."""
    return _seeds(EVALUATION_SEED, episodes)


def development_seeds(episodes: int) -> list[int]:
    """The seeds of ``episodes`` development episodes (during training, tuning): ``DEVELOPMENT_SEED + k``."""
    return _seeds(DEVELOPMENT_SEED, episodes)


def benchmark_seeds(episodes: int) -> list[int]:
    """The seeds of ``episodes`` benchmark episodes, reserved for the benchmark: ``BENCHMARK_SEED + k``."""
    return _seeds(BENCHMARK_SEED, episodes)
