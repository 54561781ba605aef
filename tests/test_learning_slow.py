"""Slow: PPO with parameter sharing actually learns the coordination (run with ``pytest -m slow``)."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from baselines.metrics import summarize
from baselines.reference import ReferencePolicy
from baselines.rollout import RandomPolicy
from baselines.seeds import development_seeds
from marine_formation_env.env import parallel_env
from training.callbacks import evaluate_policy_episodes
from training.config import apply_overrides, load_config, validate
from training.learned import ModelPolicy
from training.train import train

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)

CONFIG = Path(__file__).resolve().parents[1] / "training" / "configs" / "paper_speed_ppo.yaml"


@pytest.mark.slow
def test_ppo_speed_level_learns_most_of_the_way_to_the_reference(tmp_path: Path) -> None:
    resolved = validate(
        apply_overrides(load_config(CONFIG), {"n_timesteps": 1_500_000, "eval_freq": 0, "checkpoint_freq": 0})
    )
    model = train(resolved, tmp_path / "run", seed=0, progress=False)
    env = parallel_env(resolved["scenario"], **resolved["env_kwargs"])
    returns = {
        name: summarize(evaluate_policy_episodes(env, policy, development_seeds(4)))["return"]["mean"]
        for name, policy in {
            "learned": ModelPolicy(model, model.get_vec_normalize_env()),
            "reference": ReferencePolicy(env),
            "random": RandomPolicy(env, seed=0),
        }.items()
    }
    normalized = (returns["learned"] - returns["random"]) / (returns["reference"] - returns["random"])
    # The 15-minute benchmark reaches 1.05 (0.86 after 1.5 M vessel-steps in a 4-minute run;
    # 0.50 after 0.6 M). After 1.5 M vessel-steps the policy must
    # already have closed most of the gap between random and the paper's controller.
    assert normalized > 0.6, returns
