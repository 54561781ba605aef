"""Train a shared policy for every vessel with Stable-Baselines3.

Example::

    python -m training.train --config training/configs/paper_speed_ppo.yaml --seed 0 --out runs/paper_speed
    python -m training.train --config training/configs/paper_speed_ppo.yaml --set n_timesteps=2e5 \\
        --set env_kwargs.topology=chain --seed 1 --out runs/try
    python -m training.train --resume --out runs/paper_speed        # continue from the last checkpoint

The run folder gets ``config.yaml`` (the resolved config, with the seed),
``model.zip`` and ``vecnormalize.pkl`` (the final policy and its observation
statistics), ``best_model.zip`` (best evaluation against the reference),
``checkpoints/``, ``evaluations.csv`` and TensorBoard logs in ``tb/``
(``tensorboard --logdir runs``).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from marine_formation_env import ENV_ID
from marine_formation_env.cli import parse_overrides
from training.config import TrainConfigError, algo_class, algo_kwargs, apply_overrides, load_config, validate

__all__ = ["build_env", "latest_checkpoint", "main", "train"]


def build_env(resolved: dict[str, Any], seed: int | None) -> Any:
    """The SB3 training env: shared-policy adapter, episode monitor, optional VecNormalize."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from training.vec_env import SharedPolicyVecEnv

    venv: Any = SharedPolicyVecEnv(resolved["n_envs"], resolved["scenario"], **resolved["env_kwargs"])
    venv.seed(seed)
    venv = VecMonitor(venv)
    norm = resolved["normalize"]
    if norm:
        kwargs = norm if isinstance(norm, dict) else {}
        kwargs = {"gamma": resolved.get("gamma", 0.99), **kwargs}
        venv = VecNormalize(venv, **kwargs)
    return venv


def latest_checkpoint(out: Path) -> tuple[Path, Path | None] | None:
    """The newest ``checkpoints/model_<N>_steps.zip`` and its VecNormalize statistics, if any."""
    found = []
    for path in (out / "checkpoints").glob("model_*_steps.zip"):
        match = re.fullmatch(r"model_(\d+)_steps", path.stem)
        if match:
            found.append((int(match.group(1)), path))
    if not found:
        return None
    steps, path = max(found)
    stats = path.with_name(f"model_vecnormalize_{steps}_steps.pkl")
    return path, stats if stats.is_file() else None


def train(
    resolved: dict[str, Any],
    out: Path,
    seed: int,
    resume: bool = False,
    progress: bool = True,
    extra_callbacks: Sequence[Any] = (),
    verbose: int = 0,
    threads: int = 1,
) -> Any:
    """Train (or resume) and save into ``out``; return the model.

    ``threads`` sets torch's intra-op threads: the networks are small, and on a
    2-core machine one thread leaves the other core to the simulation (measured:
    a small ``nn.Linear`` call took ~8 ms with 2 threads under load, 0.02 ms with 1).
    """
    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    torch.set_num_threads(threads)
    from stable_baselines3.common.vec_env import VecNormalize

    from training.callbacks import ReferenceEvalCallback

    out.mkdir(parents=True, exist_ok=True)
    cls = algo_class(resolved["algo"])
    venv = build_env(resolved, seed)
    n_entries = venv.num_envs
    checkpoint = latest_checkpoint(out) if resume else None
    if resume and checkpoint is None:
        raise FileNotFoundError(f"--resume: no checkpoint in {out / 'checkpoints'}")
    if checkpoint is not None:
        model_path, stats = checkpoint
        if stats is not None and isinstance(venv, VecNormalize):
            venv = VecNormalize.load(str(stats), venv.venv)
        model = cls.load(model_path, env=venv, device="cpu", tensorboard_log=str(out / "tb"))
        print(f"resuming from {model_path} at {model.num_timesteps} steps", file=sys.stderr)
    else:
        model = cls(
            resolved["policy"],
            venv,
            seed=seed,
            device="cpu",
            verbose=verbose,
            tensorboard_log=str(out / "tb"),
            **algo_kwargs(resolved),
        )
    callbacks: list[Any] = []
    if resolved["checkpoint_freq"] > 0:
        callbacks.append(
            CheckpointCallback(
                save_freq=max(1, resolved["checkpoint_freq"] // n_entries),
                save_path=str(out / "checkpoints"),
                name_prefix="model",
                save_vecnormalize=True,
            )
        )
    if resolved["eval_freq"] > 0:
        callbacks.append(
            ReferenceEvalCallback(
                resolved["scenario"],
                resolved["env_kwargs"],
                resolved["eval_freq"],
                resolved["eval_episodes"],
                out,
                verbose=verbose,
            )
        )
    callbacks.extend(extra_callbacks)
    remaining = max(0, resolved["n_timesteps"] - model.num_timesteps)
    model.learn(
        total_timesteps=remaining,
        callback=CallbackList(callbacks),
        progress_bar=progress,
        reset_num_timesteps=checkpoint is None,
        tb_log_name="run",
    )
    model.save(out / "model.zip")
    if isinstance(venv, VecNormalize):
        venv.save(str(out / "vecnormalize.pkl"))
    venv.close()
    return model


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m training.train", description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, help="YAML config (see training/configs/)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override; dots nest")
    parser.add_argument("--seed", type=int, default=0, help="seed of the run (default 0)")
    parser.add_argument("--out", type=Path, required=True, help="run folder, e.g. runs/paper_speed")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--verbose", type=int, default=0, help="SB3 verbosity (0, 1, 2)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    args = parser.parse_args(argv)
    saved = args.out / "config.yaml"
    try:
        if args.resume:
            if not saved.is_file():
                raise TrainConfigError(f"--resume: {saved} does not exist")
            stored = yaml.safe_load(saved.read_text())[ENV_ID]
            seed = stored.pop("seed", args.seed)
            base = load_config(args.config) if args.config else stored
            resolved = validate(apply_overrides(base, parse_overrides(args.set, nest=False)))
        else:
            if args.config is None:
                raise TrainConfigError("--config is required (unless --resume)")
            if (args.out / "model.zip").exists() or (args.out / "checkpoints").exists():
                raise TrainConfigError(f"{args.out} already holds a run; use --resume or another --out")
            seed = args.seed
            resolved = validate(apply_overrides(load_config(args.config), parse_overrides(args.set, nest=False)))
    except (TrainConfigError, ValueError) as err:
        parser.error(str(err))
    args.out.mkdir(parents=True, exist_ok=True)
    saved.write_text(yaml.safe_dump({ENV_ID: {**resolved, "seed": seed}}, sort_keys=False))
    train(resolved, args.out, seed, args.resume, not args.quiet, verbose=args.verbose, threads=args.threads)
    print(f"saved {args.out / 'model.zip'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
