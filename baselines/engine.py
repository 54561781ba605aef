"""One evaluation engine: run a policy for many seeds at once and record every episode.

``evaluate_episodes`` runs one episode per seed, all seeds as one batch of
formations on ``MarineFormationVectorEnv``
(``layout="agent"``), and returns one ``Trajectory``
per seed. Formation ``b`` is reset with ``seeds[b]``, so its episode is the
one ``parallel_env(...).reset(seed=seeds[b])`` starts (tests/test_engine.py
checks it against a ParallelEnv loop). Every script that evaluates a policy
(``baselines.evaluate``, ``baselines.sweep``, the evaluation during training)
calls it.

Policies:

* a ``BatchPolicy`` (the reference, learned models,
  the random policy) acts on all vessels of all formations in one call,
  ``act_batch((B·N, dim)) -> (B·N, A)``;
* any other object with ``act(observations)`` over PettingZoo dicts is called
  once per formation with that formation's ``{agent: obs}``.

A policy with ``reset()`` is reset once before the episodes start; one with
``commands(obs)`` (the reference) also reports the speed command ``u_c`` it
implies, which is recorded at the ``force`` level where the env never sees it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from baselines.metrics import episode_metrics
from baselines.rollout import Trajectory
from marine_formation_env.core import MESSAGE_KEYS
from marine_formation_env.env import MarineFormationParallelEnv
from marine_formation_env.frontend import reward_terms
from marine_formation_env.scenarios import ScenarioConfig
from marine_formation_env.vector import MarineFormationVectorEnv

__all__ = ["episode_reports", "evaluate_episodes", "run_episode"]


def evaluate_episodes(
    policy: Any,
    config: ScenarioConfig,
    seeds: Sequence[int | None],
    options: dict[str, Any] | None = None,
    backend: str = "auto",
) -> list[Trajectory]:
    """One recorded episode of ``policy`` per seed, the seeds run as one batch.

    Args:
        policy: a batch policy or a PettingZoo-dict policy (module docstring).
        config: the scenario to run.
        seeds: one reset seed per episode (formation ``b`` gets ``seeds[b]``).
        options: ``reset`` options, as for the vector env (an ``initial_state``
            of shape ``(n, 6)`` applies to every episode).
        backend: as for ``FormationCore``.

    Returns:
        ``[Trajectory]`` in the order of ``seeds``; each ends when its
        formation terminates or is truncated.
    """
    seeds = list(seeds)
    if not seeds:
        raise ValueError("evaluate_episodes needs at least one seed")
    venv = MarineFormationVectorEnv(len(seeds), config, layout="agent", backend=backend)
    try:
        return _rollout(venv, policy, seeds, options)
    finally:
        venv.close()


def episode_reports(
    policy: Any, config: ScenarioConfig, seeds: Sequence[int], backend: str = "auto"
) -> tuple[list[dict[str, Any]], list[Trajectory]]:
    """``evaluate_episodes`` and the metrics of each episode (``episode_metrics``).

    Returns:
        ``(metrics, trajectories)``: per seed, its metrics (with ``"seed"``)
        and its recorded episode.
    """
    trajectories = evaluate_episodes(policy, config, seeds, backend=backend)
    metrics = []
    for seed, traj in zip(seeds, trajectories, strict=True):
        row = episode_metrics(traj, config)
        row["seed"] = seed
        metrics.append(row)
    return metrics, trajectories


def _rollout(
    venv: MarineFormationVectorEnv, policy: Any, seeds: list[int | None], options: dict[str, Any] | None
) -> list[Trajectory]:
    cfg, core = venv.config, venv.core
    b, n, steps, a_dim = len(seeds), cfg.n_vessels, cfg.max_steps, cfg.action_dim
    agents = [f"vessel_{j}" for j in range(n)]
    obs, _ = venv.reset(seed=seeds, options=options)
    if callable(getattr(policy, "reset", None)):
        policy.reset()
    batched = callable(getattr(policy, "act_batch", None))
    # the env reports u_c at the speed and guidance levels; only at force does the policy's own u_c say anything
    speed_of = getattr(policy, "commands", None) if cfg.action_level == "force" else None
    states = np.empty((steps + 1, b, n, 6))
    times = np.empty((steps + 1, b))
    u_c = np.full((steps, b, n), np.nan)
    actions = np.zeros((steps, b, n, a_dim))
    rewards = np.zeros((steps, b, n))
    components: dict[str, np.ndarray] = {}
    messages = {key: np.zeros((steps, b, n), dtype=np.int64) for key in MESSAGE_KEYS}
    states[0], times[0] = core.state, core.time
    length = np.full(b, steps)  # control periods each episode lasted
    alive = np.ones(b, dtype=bool)
    ended = {"terminated": np.zeros(b, dtype=bool), "truncated": np.zeros(b, dtype=bool)}
    collision = np.zeros(b, dtype=bool)
    for k in range(steps):
        if batched:
            act = np.asarray(policy.act_batch(obs), dtype=float).reshape(b * n, a_dim)
        else:
            per_formation = obs.reshape(b, n, -1)
            act = np.empty((b, n, a_dim))
            for f in range(b):
                chosen = policy.act({agent: per_formation[f, j] for j, agent in enumerate(agents)})
                act[f] = [np.asarray(chosen[agent], dtype=float).reshape(-1) for agent in agents]
            act = act.reshape(b * n, a_dim)
        if callable(speed_of):
            u_c[k] = np.asarray(speed_of(obs)["u_c"], dtype=float).reshape(b, n)
        obs, rew, term, trunc, infos = venv.step(act)
        actions[k] = np.clip(act, -1.0, 1.0).reshape(b, n, a_dim)
        rewards[k] = rew.reshape(b, n)
        for name, value in reward_terms(infos).items():
            components.setdefault(name, np.zeros((steps, b, n)))[k] = value.reshape(b, n)
        for key, value in messages.items():
            value[k] = infos[key].reshape(b, n)
        if "commanded_speed" in infos:
            u_c[k] = infos["commanded_speed"].reshape(b, n)
        states[k + 1], times[k + 1] = core.state, core.time
        done_now = alive & (term.reshape(b, n)[:, 0] | trunc.reshape(b, n)[:, 0])
        if done_now.any():
            length[done_now] = k + 1
            ended["terminated"][done_now] = term.reshape(b, n)[done_now, 0]
            ended["truncated"][done_now] = trunc.reshape(b, n)[done_now, 0]
            collision[done_now] = infos["collision"].reshape(b, n)[done_now, 0]
            alive &= ~done_now
        if not alive.any():
            break
    out = []
    for f in range(b):
        t_len = int(length[f])
        t = times[: t_len + 1, f].copy()
        out.append(
            Trajectory(
                t=t,
                state=states[: t_len + 1, f].copy(),
                u_d=np.asarray(cfg.u_d.value(t), dtype=float),
                commanded_speed=u_c[:t_len, f].copy(),
                actions=actions[:t_len, f].copy(),
                rewards=rewards[:t_len, f].copy(),
                components={name: value[:t_len, f].copy() for name, value in components.items()},
                terminated=bool(ended["terminated"][f]),
                truncated=bool(ended["truncated"][f]),
                collision=bool(collision[f]),
                messages={key: value[:t_len, f].copy() for key, value in messages.items()},
            )
        )
    return out


def run_episode(
    env: MarineFormationParallelEnv,
    policy: Any,
    seed: int | None = None,
    options: dict[str, Any] | None = None,
) -> Trajectory:
    """Roll out one episode of ``policy`` on ``env``'s scenario and record it.

    The episode is the one ``env.reset(seed=seed, options=options)`` starts;
    it runs on the evaluation engine (``evaluate_episodes``,
    one formation, ``env``'s backend), which leaves ``env`` itself untouched.

    Args:
        env: a ParallelEnv of this package (its configuration and backend are used).
        policy: has ``act(observations)`` or ``act_batch``; optionally
            ``commands`` and ``reset()`` (see ``baselines.engine``).
        seed: the reset seed.
        options: the reset options.
    """
    return evaluate_episodes(policy, env.config, [seed], options=options, backend=env.core.backend)[0]
