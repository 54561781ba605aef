"""Train a shared policy for every vessel with Stable-Baselines3.

Example::

    python -m training.train --config training/configs/paper_speed_ppo.yaml --seed 0 --out runs/paper_speed
    python -m training.train --config training/configs/paper_speed_ppo.yaml --set n_timesteps=2e5 \\
        --set env_kwargs.topology=chain --seed 1 --out runs/try
    python -m training.train --resume --out runs/paper_speed        # continue from the last checkpoint
    python -m training.train --resume --out runs/paper_speed --set n_timesteps=4e6   # ... and train longer

The run folder gets ``config.yaml`` (the resolved config with ``trainer: sb3``,
``env_id`` and the seed: ``training.run_folder.write_config``), ``model.zip``
and ``vecnormalize.pkl`` (the final policy and its observation statistics),
``evaluation.json`` (the final policy and the reference on
``baselines.seeds.evaluation_seeds(eval_episodes)``, written when training ends),
``best_model.zip`` + ``best_vecnormalize.pkl`` (best evaluation against the
reference; ``best_model.json`` records its score and step), ``checkpoints/``
(``model_<N>_steps.zip`` + ``model_vecnormalize_<N>_steps.pkl``, including one
at step 0), ``evaluations.csv`` (the evaluations during training, on
``baselines.seeds.development_seeds``), ``progress.csv`` (the learning curve,
one row per rollout: ``training.run_folder.PROGRESS_COLUMNS``,
``ProgressLog``) and TensorBoard
logs in ``tb/`` (``tensorboard --logdir runs``).

The run folder never holds half-written files: every file above is written
to a temporary file in the same folder, flushed and fsync-ed, then renamed
over its name (``training.run_folder``); the three ``best_*`` files, and
``model.zip`` with ``vecnormalize.pkl``, are replaced together (a journal that
the next start completes). A run killed at any instant can be resumed.

Rules:

* A new run refuses a folder that holds anything of another run
  (``config.yaml``, ``model.zip``, ``vecnormalize.pkl``, ``best_model.*``,
  ``best_vecnormalize.pkl``, ``evaluations.csv``, ``progress.csv``, ``evaluation.json``, ``tb/``,
  ``checkpoints/``);
  ``--overwrite`` removes those first (only once the new config has been
  checked, by building the algorithm on the real env).
* ``--resume`` continues from the newest *readable* checkpoint: empty,
  truncated or otherwise unreadable checkpoint files are skipped with one line
  each saying why, and temporary files of interrupted writes are removed.
  Rows of ``evaluations.csv`` and ``progress.csv`` after the checkpoint's
  step are dropped (the files stay monotone in timesteps) and the best score is read back from
  ``best_model.json``, so ``best_model.zip`` is only replaced by a better
  model. The run's stored config is used; ``--config``/``--set`` may change
  only ``n_timesteps``, ``eval_freq``, ``eval_episodes`` and
  ``checkpoint_freq`` (any other difference, or another ``--seed``, is refused
  before anything is written, naming each key with its old and new value).
* Ctrl-C (SIGINT) stops training at the next step, saves a checkpoint and
  exits with status 130 (a second Ctrl-C stops at once, keeping the last
  periodic checkpoint); ``--resume`` continues from it.
* Bad input (malformed YAML, unknown keys, values the algorithm rejects,
  ``--threads 0``, ``--seed -5``, ...) is reported as one line
  ``python -m training.train: error: ...`` with exit status 2, before anything
  is written.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from marine_formation_env.cli import ArgumentParser, int_at_least, parse_overrides
from marine_formation_env.scenarios import make_config
from training import run_folder
from training.config import (
    RESUMABLE_KEYS,
    TrainConfigError,
    algo_class,
    algo_kwargs,
    apply_overrides,
    config_differences,
    curriculum_spread,
    load_config,
    team_overrides,
    training_env_kwargs,
    validate,
)
from training.learned import evaluate_run, load_sb3_run

__all__ = [
    "NoCheckpointError",
    "TrainingInterrupted",
    "build_env",
    "build_model",
    "check_buildable",
    "latest_checkpoint",
    "main",
    "train",
]

PROG = "python -m training.train"


class NoCheckpointError(FileNotFoundError):
    """``--resume`` found no readable checkpoint in the run folder."""


class TrainingInterrupted(KeyboardInterrupt):
    """Training stopped on SIGINT after saving the checkpoint ``path`` at ``steps`` vessel-steps."""

    def __init__(self, path: Path, steps: int) -> None:
        super().__init__(f"interrupted at {steps} steps; saved {path}")
        self.path = path
        self.steps = steps


def build_env(resolved: dict[str, Any], seed: int | None) -> Any:
    """The SB3 training env: shared-policy adapter, episode monitor, optional VecNormalize."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from training.vec_env import ResidualVecEnv, SharedPolicyVecEnv, TeamsVecEnv

    teams = [  # each team's preset and overrides, with train_reward's shaping
        SharedPolicyVecEnv(resolved["n_envs"], scenario, **training_env_kwargs(resolved, kw))
        for scenario, kw in team_overrides(resolved)
    ]
    venv: Any = teams[0] if len(teams) == 1 else TeamsVecEnv(teams)
    venv.seed(seed)
    if resolved["residual"]:  # on raw observations, inside the normalization
        venv = ResidualVecEnv(venv, make_config(resolved["scenario"], **resolved["env_kwargs"]))
    venv = VecMonitor(venv)
    norm = resolved["normalize"]
    if norm:
        kwargs = norm if isinstance(norm, dict) else {}
        kwargs = {"gamma": resolved.get("gamma", 0.99), **kwargs}
        venv = VecNormalize(venv, **kwargs)
    return venv


def build_model(resolved: dict[str, Any], venv: Any, seed: int, verbose: int = 0, tensorboard_log: Any = None) -> Any:
    """The algorithm on ``venv``; whatever its constructor rejects becomes a ``TrainConfigError``."""
    cls = algo_class(resolved["algo"])
    try:
        model = cls(
            resolved["policy"],
            venv,
            seed=seed,
            device="cpu",
            verbose=verbose,
            tensorboard_log=tensorboard_log,
            **algo_kwargs(resolved),
        )
    except Exception as err:
        raise TrainConfigError(f"{resolved['algo']} rejects this config: {type(err).__name__}: {err}") from None
    if resolved.get("transmit_bias") is not None:  # the Gaussian's mean of the last action entry starts there
        import torch

        with torch.no_grad():
            model.policy.action_net.bias[-1] = resolved["transmit_bias"]
    return model


def check_buildable(resolved: dict[str, Any], seed: int) -> None:
    """Build the env and the algorithm once (nothing is written), so bad values fail before the run starts."""
    try:
        venv = build_env(resolved, seed)
    except Exception as err:
        raise TrainConfigError(f"cannot build the training env: {type(err).__name__}: {err}") from None
    try:
        build_model(resolved, venv, seed)
    finally:
        venv.close()


def latest_checkpoint(out: Path) -> tuple[Path, Path | None] | None:
    """The newest readable ``checkpoints/model_<N>_steps.zip`` and its VecNormalize statistics, if any."""
    for checkpoint in run_folder.list_checkpoints(out):
        has_stats = checkpoint.stats.is_file()
        if run_folder.checkpoint_problem(checkpoint, needs_stats=has_stats) is None:
            return checkpoint.model, checkpoint.stats if has_stats else None
    return None


def _one_line(err: BaseException) -> str:
    return f"{type(err).__name__}: {' '.join(str(err).split())}"


def _load_newest_checkpoint(resolved: dict[str, Any], out: Path, venv: Any) -> tuple[Any, Any, int]:
    """``(model, venv, steps)`` from the newest checkpoint that loads; one stderr line per skipped one."""
    from stable_baselines3.common.vec_env import VecNormalize

    cls = algo_class(resolved["algo"])
    normalized = isinstance(venv, VecNormalize)
    candidates = run_folder.list_checkpoints(out)
    for checkpoint in candidates:
        problem = run_folder.checkpoint_problem(checkpoint, needs_stats=normalized)
        if problem is None:
            try:
                env = VecNormalize.load(str(checkpoint.stats), venv.venv) if normalized else venv
                model = cls.load(checkpoint.model, env=env, device="cpu", tensorboard_log=str(out / "tb"))
            except Exception as err:
                problem = f"cannot be loaded ({_one_line(err)})"
            else:
                print(f"resuming from {checkpoint.model} at {model.num_timesteps} steps", file=sys.stderr)
                return model, env, checkpoint.steps
        print(f"skipping checkpoint {checkpoint.model}: {problem}", file=sys.stderr)
    found = f"none of its {len(candidates)} checkpoint(s) is readable" if candidates else "it holds no checkpoint"
    raise NoCheckpointError(f"--resume: cannot continue the run in {out}: {found}; start it over with --overwrite")


def train(
    resolved: dict[str, Any],
    out: Path,
    seed: int,
    resume: bool = False,
    progress: bool = True,
    extra_callbacks: Sequence[Any] = (),
    verbose: int = 0,
    threads: int = 1,
    minutes: float | None = None,
) -> Any:
    """Train (or resume) and save into ``out``; return the model.

    ``minutes`` also stops training after that much wall time (the learning
    benchmarks' budget), and a ``lin_<x>`` learning rate then falls to 0 over
    whichever of it and ``n_timesteps`` runs out first
    (``BudgetSchedule``); a curriculum over the initial state
    (``initial_state_curriculum``) then runs over whichever of it and
    ``n_timesteps`` runs out first (``InitialStateCurriculum``).
    Before the first rollout the training env is set to the curriculum's first
    spread, so the very first episodes follow it too.

    ``threads`` sets torch's intra-op threads: the networks are small, and on a
    2-core machine one thread leaves the other core to the simulation (measured:
    a small ``nn.Linear`` call took ~8 ms with 2 threads under load, 0.02 ms with 1).

    ``out/config.yaml`` (``trainer: sb3``, ``env_id``, ``seed`` and ``resolved``) is written once the model is
    built or loaded, before training; ``out/evaluation.json`` once training has ended
    (``training.learned.evaluate_run``). Stale temporary files in ``out`` are removed first and an interrupted
    update of the best model is completed (``training.run_folder.recover``).

    Raises:
        NoCheckpointError: ``resume`` and no checkpoint of ``out`` loads.
        TrainConfigError: the algorithm's constructor rejects ``resolved``.
        TrainingInterrupted: SIGINT (in the main thread) stopped training; a
            checkpoint was saved first.
    """
    import torch

    torch.set_num_threads(threads)
    from stable_baselines3.common.callbacks import CallbackList

    from training.callbacks import (
        AtomicCheckpointCallback,
        InitialStateCurriculum,
        LearningRateBudget,
        ProgressLog,
        ReferenceEvalCallback,
        StopRequest,
        WallClockBudget,
    )

    out.mkdir(parents=True, exist_ok=True)
    for note in run_folder.recover(out):
        print(note, file=sys.stderr)
    venv = build_env(resolved, seed)
    if resume:
        model, venv, steps = _load_newest_checkpoint(resolved, out, venv)
        dropped = run_folder.truncate_evaluations(out / "evaluations.csv", steps)
        if dropped:
            print(f"dropped {dropped} row(s) of evaluations.csv after step {steps}", file=sys.stderr)
    else:
        model = build_model(resolved, venv, seed, verbose=verbose, tensorboard_log=str(out / "tb"))
    run_folder.write_config(out, "sb3", resolved, seed)
    stop = StopRequest()
    log = ProgressLog(out)
    if resume:
        log.resume(int(model.num_timesteps))
    callbacks: list[Any] = [stop, log]
    if resolved["checkpoint_freq"] > 0:
        if not resume:
            run_folder.save_checkpoint(model, out, 0)  # resumable from the start
        callbacks.append(AtomicCheckpointCallback(out, resolved["checkpoint_freq"], verbose=verbose))
    if resolved["eval_freq"] > 0:
        evaluation = ReferenceEvalCallback(
            resolved["scenario"],
            resolved["env_kwargs"],
            resolved["eval_freq"],
            resolved["eval_episodes"],
            out,
            verbose=verbose,
        )
        if resume:
            evaluation.restore_best()
        callbacks.append(evaluation)
    seconds = None if minutes is None else 60.0 * float(minutes)
    if seconds is not None:
        callbacks.extend([WallClockBudget(seconds), LearningRateBudget(seconds)])
    curriculum = resolved.get("initial_state_curriculum")
    if curriculum is not None:
        total = max(1, resolved["n_timesteps"])
        # before learn()'s first reset: the first episodes start at the curriculum's spread as well
        venv.unwrapped.set_initial_spread(curriculum_spread(curriculum, model.num_timesteps / total))
        callbacks.append(InitialStateCurriculum(curriculum, total, seconds))
    callbacks.extend(extra_callbacks)

    def on_sigint(signum: int, frame: Any) -> None:
        if stop.requested:  # a second Ctrl-C: stop now
            raise KeyboardInterrupt
        stop.requested = True

    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        remaining = max(0, resolved["n_timesteps"] - model.num_timesteps)
        model.learn(
            total_timesteps=remaining,
            callback=CallbackList(callbacks),
            progress_bar=progress,
            reset_num_timesteps=not resume,
            tb_log_name="run",
        )
        if stop.requested:
            path = run_folder.save_checkpoint(model, out)
            venv.close()
            raise TrainingInterrupted(path, int(model.num_timesteps))
        run_folder.save_final(model, out)  # model.zip and vecnormalize.pkl, replaced together
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
    venv.close()
    policy, _ = load_sb3_run(out)
    wall_time = float(log.rows[-1]["wall_time_s"]) if log.rows else 0.0
    evaluate_run(out, policy, resolved, vessel_steps=int(model.num_timesteps), wall_time_s=wall_time)
    return model


def _resume_config(out: Path, config: Path | None, overrides: dict[str, Any], seed: int | None) -> tuple[Any, int]:
    """The resolved config and seed of ``--resume``; refuses changes beyond ``RESUMABLE_KEYS``."""
    saved = out / run_folder.CONFIG_FILE
    if not saved.is_file():
        raise TrainConfigError(f"--resume: {saved} does not exist")
    try:
        stored = run_folder.read_config(out)
    except run_folder.RunFolderError as err:
        raise TrainConfigError(f"--resume: {err}") from None
    if stored["trainer"] != "sb3":
        raise TrainConfigError(f"--resume: {out} is a run of the {stored['trainer']} trainer, not of {PROG}")
    stored_seed = stored.pop("seed", 0)
    stored = {k: v for k, v in stored.items() if k not in ("trainer", "env_id")}
    base = load_config(config) if config is not None else stored
    resolved = validate(apply_overrides(base, overrides))
    changed = [
        (key, old, new) for key, old, new in config_differences(validate(stored), resolved)
        if key not in RESUMABLE_KEYS
    ]  # fmt: skip
    if seed is not None and seed != stored_seed:
        changed.append(("seed", stored_seed, seed))
    if changed:
        listed = ", ".join(f"{key} ({old!r} → {new!r})" for key, old, new in changed)
        raise TrainConfigError(
            f"--resume: the config differs from {saved} in {listed}; only {', '.join(RESUMABLE_KEYS)} may change "
            "when resuming (start a new run with --overwrite or another --out)"
        )
    return resolved, stored_seed


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, help="YAML config (see training/configs/)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override; dots nest")
    parser.add_argument("--seed", type=int_at_least(0), default=None, help="seed of the run (default 0)")
    parser.add_argument("--out", type=Path, required=True, help="run folder, e.g. runs/paper_speed")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    mode.add_argument("--overwrite", action="store_true", help="remove the run already in --out, then start anew")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--verbose", type=int, choices=(0, 1, 2), default=0, help="SB3 verbosity (0, 1, 2)")
    parser.add_argument("--threads", type=int_at_least(1), default=1, help="torch threads (default 1)")
    args = parser.parse_args(argv)
    out: Path = args.out
    try:
        if out.exists() and not out.is_dir():
            raise TrainConfigError(f"--out {str(out)!r} is a file, not a folder")
        overrides = parse_overrides(args.set, nest=False)
        if args.resume:
            resolved, seed = _resume_config(out, args.config, overrides, args.seed)
        else:
            if args.config is None:
                raise TrainConfigError("--config is required (unless --resume)")
            seed = 0 if args.seed is None else args.seed
            resolved = validate(apply_overrides(load_config(args.config), overrides))
            present = run_folder.present_artifacts(out) if out.is_dir() else []
            if present and not args.overwrite:
                raise TrainConfigError(
                    f"{out} already holds a run ({', '.join(present)}); use --resume to continue it, "
                    "--overwrite to replace it, or another --out"
                )
        import torch

        torch.set_num_threads(args.threads)
        check_buildable(resolved, seed)
    except (TrainConfigError, ValueError) as err:
        parser.error(str(err))
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted before training started; nothing was written", file=sys.stderr)
        return 130
    try:
        if args.overwrite and out.is_dir():
            removed = run_folder.present_artifacts(out)
            run_folder.remove_artifacts(out)
            if removed:
                print(f"removed the previous run's {', '.join(removed)} from {out}", file=sys.stderr)
        train(
            resolved,
            out,
            seed,
            args.resume,
            not args.quiet,
            verbose=args.verbose,
            threads=args.threads,
        )
    except NoCheckpointError as err:
        parser.error(str(err))
    except TrainingInterrupted as stop:
        print(
            f"{PROG}: interrupted at {stop.steps} steps; saved checkpoint {stop.path}; "
            f"continue with: {PROG} --resume --out {out}",
            file=sys.stderr,
        )
        return 130
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted before a checkpoint could be saved; {out} keeps its earlier ones", file=sys.stderr)
        return 130
    print(f"saved {out / 'model.zip'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
