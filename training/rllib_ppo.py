"""PPO with RLlib (new API stack), one policy shared by every vessel, on one machine or a Ray cluster.

Each env runner steps its own copies of the ParallelEnv through RLlib's
``ParallelPettingZooEnv``; every vessel maps to the one module ``shared``
(parameter sharing, as in the SB3 and TorchRL pipelines); the learner runs in
this process. Install with the ``rllib`` extra (``pip install -c
constraints-ecosystem.txt -e ".[rllib]"``)::

    python -m training.rllib_ppo --config training/configs/rllib/paper_speed_ppo.yaml --seed 0 \\
        --out runs/rllib_paper_speed
    python -m training.rllib_ppo --config training/configs/rllib/paper_speed_ppo.yaml \\
        --set num_env_runners=8 --address HEAD_IP:6379 --out runs/rllib_cluster

``--address`` joins a running Ray cluster (``HOST:PORT``, or ``auto`` on a
node of it); without it a Ray instance of this process is started and stopped
with it. Starting a cluster (``baselines.ray_cluster``)::

    ray start --head --port=6379                 # on the head node
    ray start --address=HEAD_IP:6379             # on every other node

The config file holds one mapping under ``MarineFormation-v1`` (the same
``--set KEY=VALUE`` grammar as ``training.train``, dots nest; unknown keys and
bad values are refused by name):

| key | meaning | default |
|---|---|---|
| ``scenario``, ``env_kwargs`` | the scenario and its overrides, as for ``parallel_env`` | ``paper``, ``{}`` |
| ``num_env_runners`` | Ray actors that step envs (0: sample in this process) | 2 |
| ``n_envs`` | formations per env runner (RLlib's ``num_envs_per_env_runner``) | 1 |
| ``env_runner_resources`` | custom Ray resources each env runner needs (places them on nodes that have them) | ``{}`` |
| ``train_batch_size`` | formation-steps per iteration (vessel-steps = × n) | 4000 |
| ``batch_size``, ``n_epochs`` | SGD minibatch [vessel-steps], passes over each batch | 1000, 4 |
| ``iterations`` | training iterations, or null (then ``minutes`` or ``total_env_steps`` stops) | null |
| ``total_env_steps`` | formation-steps of the run | 1.0e6 |
| ``minutes`` | wall-clock limit (stops after the iteration that passes it), or null | null |
| ``hidden`` | hidden layers of the policy and value networks | ``[64, 64]`` |
| ``learning_rate``, ``gamma``, ``gae_lambda`` | Adam learning rate, discount, GAE λ | 3e-4, 0.99, 0.95 |
| ``clip_range``, ``ent_coef``, ``max_grad_norm`` | PPO clip range, entropy bonus, gradient clipping | 0.2, 0.0, 1.0 |
| ``eval_episodes`` | evaluation episodes at the end (``baselines.seeds.evaluation_seeds``), against the reference | 4 |

The keys are SB3's names, as in every trainer of this project; the trainer maps them to RLlib's
(``num_envs_per_env_runner``, ``minibatch_size``, ``num_epochs``, ``lr``, ``lambda_``, ``clip_param``,
``entropy_coeff``, ``grad_clip``), and a config that uses RLlib's names is refused naming the new one.

The run folder (``training.run_folder``) gets ``config.yaml`` (resolved, with
``trainer: rllib`` and the seed), ``checkpoint/`` (RLlib's own algorithm checkpoint,
``Algorithm.from_checkpoint`` restores it), ``progress.csv`` (per iteration: the shared
columns, then ``iteration`` and ``env_steps``; ``episode_return_mean`` is RLlib's mean episode
return, the sum over the team, divided by the number of vessels), ``cluster.json`` (the Ray
nodes, and the node of every env runner) and ``evaluation.json``
(``training.learned.evaluate_run``). ``python -m baselines.evaluate
--policy RUN_FOLDER`` evaluates it next to the reference.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from baselines.ray_cluster import RAY_MISSING, connect
from baselines.runs import run_folder_of
from marine_formation_env.atomic import atomic_write_text
from marine_formation_env.cli import ArgumentParser, report_error
from marine_formation_env.env import parallel_env
from marine_formation_env.scenarios import make_config
from training.config import (
    RENAMED_KEYS,
    TrainConfigError,
    _hidden,
    _number,
    _positive,
    _whole,
    add_run_arguments,
    check_ppo_keys,
    check_renamed,
    config_from_arguments,
)
from training.learned import evaluate_run
from training.run_folder import PROGRESS_FILE, read_config, write_config, write_progress

__all__ = [
    "DEFAULTS",
    "ENV_NAME",
    "MODULE_ID",
    "RLlibPolicy",
    "load_rllib_policy",
    "load_rllib_run",
    "make_env",
    "resolve",
    "train",
]

#: Every key a config may hold, with its default.
DEFAULTS: dict[str, Any] = {
    "scenario": "paper",
    "env_kwargs": {},
    "num_env_runners": 2,
    "n_envs": 1,
    "env_runner_resources": {},
    "train_batch_size": 4000,
    "batch_size": 1000,
    "n_epochs": 4,
    "iterations": None,
    "total_env_steps": 1_000_000,
    "minutes": None,
    "hidden": [64, 64],
    "learning_rate": 3e-4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "ent_coef": 0.0,
    "max_grad_norm": 1.0,
    "eval_episodes": 4,
}

#: RLlib's names of this trainer's keys that ``training.config.RENAMED_KEYS`` does not list.
RENAMED = {**RENAMED_KEYS, "minibatch_size": "batch_size"}
#: The trainer's own columns of ``progress.csv``, after ``training.run_folder.PROGRESS_COLUMNS``.
PROGRESS_OWN_COLUMNS = ("iteration", "env_steps")

#: The name the env is registered under with Ray Tune's registry.
ENV_NAME = "marine_formation_env"
#: The one RLModule every vessel maps to.
MODULE_ID = "shared"
CHECKPOINT_DIR = "checkpoint"
#: Where the shared module sits inside an algorithm checkpoint.
MODULE_PATH = Path("learner_group") / "learner" / "rl_module" / MODULE_ID


def resolve(raw: dict[str, Any], seed: int) -> dict[str, Any]:
    """The config with defaults filled in and every value checked (``TrainConfigError`` names the bad one)."""
    check_renamed(raw, RENAMED)
    unknown = sorted(set(raw) - set(DEFAULTS) - {"seed"})
    if unknown:
        raise TrainConfigError(f"unknown key(s) {unknown}; valid keys: {sorted(DEFAULTS)}")
    cfg = {**DEFAULTS, **{k: v for k, v in raw.items() if k != "seed"}, "seed": seed}
    if not isinstance(cfg["env_kwargs"], dict):
        raise TrainConfigError(f"env_kwargs must be a mapping, got {cfg['env_kwargs']!r}")
    cfg["num_env_runners"] = _whole("num_env_runners", cfg["num_env_runners"], 0)
    for key in ("n_envs", "train_batch_size", "batch_size", "n_epochs", "eval_episodes"):
        cfg[key] = _whole(key, cfg[key], 1)
    cfg["total_env_steps"] = _whole("total_env_steps", cfg["total_env_steps"], 1)
    if cfg["iterations"] is not None:
        cfg["iterations"] = _whole("iterations", cfg["iterations"], 1)
    if cfg["minutes"] is not None:
        cfg["minutes"] = _positive("minutes", cfg["minutes"])
    cfg["learning_rate"] = _positive("learning_rate", cfg["learning_rate"])
    check_ppo_keys(cfg)
    cfg["hidden"] = _hidden(cfg["hidden"])
    resources = cfg["env_runner_resources"]
    if not isinstance(resources, dict) or not all(
        isinstance(k, str) and _number(f"env_runner_resources.{k}", v) > 0 for k, v in resources.items()
    ):
        raise TrainConfigError(f"env_runner_resources must map resource names to amounts > 0, got {resources!r}")
    try:
        scenario = make_config(cfg["scenario"], **cfg["env_kwargs"])
    except (ValueError, TypeError) as err:
        raise TrainConfigError(f"scenario {cfg['scenario']!r} with env_kwargs {cfg['env_kwargs']}: {err}") from err
    if cfg["batch_size"] > cfg["train_batch_size"] * scenario.n_vessels:
        raise TrainConfigError(
            f"batch_size = {cfg['batch_size']} vessel-steps exceeds a batch of "
            f"{cfg['train_batch_size']} × {scenario.n_vessels} vessel-steps"
        )
    return cfg


def make_env(env_config: dict[str, Any]) -> Any:
    """The env creator RLlib calls on every env runner: ``ParallelPettingZooEnv(parallel_env(...))``."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    return ParallelPettingZooEnv(parallel_env(env_config["scenario"], **env_config["env_kwargs"]))


def _shared_module(*_args: Any, **_kwargs: Any) -> str:
    return MODULE_ID


def algorithm_config(cfg: dict[str, Any]) -> Any:
    """RLlib's ``PPOConfig`` for the resolved ``cfg``."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.tune.registry import register_env

    register_env(ENV_NAME, make_env)
    return (
        PPOConfig()
        .environment(ENV_NAME, env_config={"scenario": cfg["scenario"], "env_kwargs": cfg["env_kwargs"]})
        .multi_agent(policies={MODULE_ID}, policy_mapping_fn=_shared_module)
        .env_runners(
            num_env_runners=cfg["num_env_runners"],
            num_envs_per_env_runner=cfg["n_envs"],
            custom_resources_per_env_runner=dict(cfg["env_runner_resources"]),
            rollout_fragment_length="auto",
        )
        .training(
            train_batch_size_per_learner=cfg["train_batch_size"],
            minibatch_size=cfg["batch_size"],
            num_epochs=cfg["n_epochs"],
            lr=cfg["learning_rate"],
            gamma=cfg["gamma"],
            lambda_=cfg["gae_lambda"],
            clip_param=cfg["clip_range"],
            entropy_coeff=cfg["ent_coef"],
            grad_clip=cfg["max_grad_norm"],
        )
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=cfg["hidden"], fcnet_activation="tanh"))
        .debugging(seed=cfg["seed"])
    )


class RLlibPolicy:
    """The shared module of an RLlib PPO checkpoint as a batch policy (``baselines``): the Gaussian's mean.

    ``act_batch((..., dim)) -> (..., A)``, clipped to [−1, 1] as RLlib's
    env runners clip before they unsquash into the action space (which is
    [−1, 1] at every level). Any number of formations and vessels per call.
    """

    def __init__(self, module: Any, observation_dim: int, action_dim: int) -> None:
        self.module = module
        self.observation_dim = observation_dim
        self.action_dim = action_dim

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        import torch
        from ray.rllib.core.columns import Columns

        flat = torch.as_tensor(np.asarray(obs, dtype=np.float32).reshape(-1, obs.shape[-1]))
        with torch.no_grad():
            out = self.module.forward_inference({Columns.OBS: flat})
        mean = out[Columns.ACTION_DIST_INPUTS][:, : self.action_dim].numpy()
        return np.clip(mean, -1.0, 1.0).astype(np.float32).reshape(*obs.shape[:-1], self.action_dim)

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The PettingZoo-dict form of ``act_batch``."""
        agents = list(observations)
        actions = self.act_batch(np.stack([observations[a] for a in agents]))
        return dict(zip(agents, actions, strict=True))


def load_rllib_policy(folder: str | Path) -> tuple[RLlibPolicy, dict[str, Any]]:
    """The policy of a ``training.rllib_ppo`` run folder (or of its ``checkpoint``) and the run's config.

    Only the shared module is loaded (``RLModule.from_checkpoint``): no Ray
    cluster is started.

    Raises:
        FileNotFoundError: no RLlib checkpoint in the folder.
        ValueError: the checkpoint is not readable as this trainer's.
    """
    folder = Path(folder)
    run = folder.parent if folder.name == CHECKPOINT_DIR else folder
    module_dir = run / CHECKPOINT_DIR / MODULE_PATH
    if not module_dir.is_dir():
        raise FileNotFoundError(f"{module_dir} does not exist (not a training.rllib_ppo run folder)")
    try:
        from ray.rllib.core.rl_module.rl_module import RLModule
    except ImportError:
        raise ImportError(RAY_MISSING) from None
    try:
        config = read_config(run)
        module = RLModule.from_checkpoint(module_dir)
        observation_dim = int(module.observation_space.shape[0])
        action_dim = int(module.action_space.shape[0])
    except (OSError, KeyError, ValueError, TypeError, AttributeError) as err:
        raise ValueError(f"cannot load the RLlib policy in {str(run)!r}: {type(err).__name__}: {err}") from err
    module.eval()
    return RLlibPolicy(module, observation_dim, action_dim), config


def load_rllib_run(run: Path, deterministic: bool = True) -> tuple[RLlibPolicy, dict[str, Any]]:
    """The policy of a ``training.rllib_ppo`` run folder and its ``config.yaml``.

    The loader of the ``rllib`` entry point of ``marine_formation_env.trainers``; the policy acts with the
    Gaussian's mean (deterministically) only.

    Raises:
        ValueError: ``deterministic`` is false, or the checkpoint is not readable as this trainer's.
    """
    run = run_folder_of(run)
    if not deterministic:
        raise ValueError(f"the policy of the RLlib run {str(run)!r} acts deterministically only")
    return load_rllib_policy(run)


def _env_runner_nodes(algo: Any) -> list[str]:
    """The Ray node id of every remote env runner."""
    group = algo.env_runner_group
    if group.num_remote_env_runners() == 0:
        return []
    return list(group.foreach_env_runner(_node_id, local_env_runner=False))


def _node_id(_runner: Any) -> str:
    import ray

    return str(ray.get_runtime_context().get_node_id())


def train(cfg: dict[str, Any], out: Path, address: str | None = None, progress: bool = True) -> dict[str, Any]:
    """Train with the resolved ``cfg`` into ``out``; returns the evaluation summary (also in ``evaluation.json``)."""
    from tqdm import tqdm

    ray = connect(address or "local")
    n = make_config(cfg["scenario"], **cfg["env_kwargs"]).n_vessels
    out.mkdir(parents=True, exist_ok=True)
    write_config(out, "rllib", cfg, cfg["seed"])
    algo = algorithm_config(cfg).build_algo()
    try:
        nodes = {
            "nodes": {
                str(node["NodeID"]): {"address": node.get("NodeManagerAddress"), "resources": node.get("Resources", {})}
                for node in ray.nodes()
                if node.get("Alive")
            },
            "driver": str(ray.get_runtime_context().get_node_id()),
            "env_runners": _env_runner_nodes(algo),
        }
        atomic_write_text(out / "cluster.json", json.dumps(nodes, indent=2) + "\n")
        rows: list[dict[str, Any]] = []
        begin = time.perf_counter()
        total = cfg["iterations"] * cfg["train_batch_size"] if cfg["iterations"] else cfg["total_env_steps"]
        bar = tqdm(total=total, unit="steps", disable=not progress, dynamic_ncols=True)
        steps = 0
        while True:
            result = algo.train()
            runners = result.get("env_runners", {})
            new_steps = int(runners.get("num_env_steps_sampled_lifetime", steps + cfg["train_batch_size"]))
            bar.update(new_steps - steps)
            steps = new_steps
            elapsed = time.perf_counter() - begin
            team_return = runners.get("episode_return_mean")  # RLlib's: summed over every vessel of the team
            rows.append(
                {
                    "vessel_steps": steps * n,
                    "wall_time_s": round(elapsed, 3),
                    "episode_return_mean": "" if team_return is None else float(team_return) / n,
                    "episodes": int(runners.get("num_episodes", 0)) * n,  # counted per vessel, as the others
                    "iteration": len(rows) + 1,
                    "env_steps": steps,
                }
            )
            if rows[-1]["episode_return_mean"] != "":
                bar.set_postfix(ret=f"{rows[-1]['episode_return_mean']:.1f}")
            if cfg["iterations"] is not None and len(rows) >= cfg["iterations"]:
                break
            if cfg["iterations"] is None and steps >= cfg["total_env_steps"]:
                break
            if cfg["minutes"] is not None and elapsed >= 60.0 * cfg["minutes"]:
                break
        bar.close()
        _save_progress(out, rows)
        _save_checkpoint(algo, out)
    finally:
        algo.stop()
    policy, _ = load_rllib_policy(out)
    last = rows[-1]
    return evaluate_run(out, policy, cfg, vessel_steps=last["vessel_steps"], wall_time_s=last["wall_time_s"])


def _save_progress(out: Path, rows: list[dict[str, Any]]) -> None:
    write_progress(out / PROGRESS_FILE, rows, PROGRESS_OWN_COLUMNS)


def _save_checkpoint(algo: Any, out: Path) -> None:
    """RLlib's checkpoint, written beside and then renamed into place (never half-written)."""
    import shutil

    final = out / CHECKPOINT_DIR
    staging = out / f".{CHECKPOINT_DIR}.partial"
    shutil.rmtree(staging, ignore_errors=True)
    algo.save_to_path(str(staging.resolve()))
    old = out / f".{CHECKPOINT_DIR}.old"
    shutil.rmtree(old, ignore_errors=True)
    if final.exists():
        final.rename(old)
    staging.rename(final)
    shutil.rmtree(old, ignore_errors=True)


# ----------------------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    prog = "python -m training.rllib_ppo"
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_run_arguments(parser)
    parser.add_argument(
        "--address", default=None, help="Ray cluster to join: HOST:PORT or 'auto' (default: a Ray of this process)"
    )
    args = parser.parse_args(argv)
    cfg = config_from_arguments(args, resolve, prog)
    if (args.out / CHECKPOINT_DIR).exists() and not args.overwrite:
        report_error(prog, f"{args.out} already holds a run ({CHECKPOINT_DIR}/); pass --overwrite to replace it")
    try:
        summary = train(cfg, args.out, address=args.address, progress=not args.no_progress)
    except (ImportError, ConnectionError, ValueError) as err:
        report_error(prog, str(err))
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
