"""Export a trained policy as a pretrained ``.npz`` file that runs with numpy alone.

``export_run`` reads a run folder of ``training.train`` (SB3) or
``training.torchrl_ppo`` (the trainer is its ``config.yaml``'s ``trainer``
field), copies the deterministic network's weights, observation statistics
and action units into a ``MLPPolicy``, and writes
it with a header saying what it expects and what it scored
(``baselines.pretrained`` describes the format)::

    python -m training.export runs/paper_speed --name my_policy --folder runs/exported
    python -m baselines.evaluate --policy runs/exported/my_policy.npz --policy reference --episodes 10
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from torch import nn

from baselines.pretrained import MLPPolicy, PretrainedInfo, save_pretrained
from baselines.residual import ResidualPolicy
from baselines.runs import run_folder_of, trainer_of
from baselines.seeds import evaluation_seeds
from marine_formation_env.cli import ArgumentParser
from marine_formation_env.scenarios import make_config
from training.inputs import InputMask
from training.learned import evaluation_summary, load_learned_policy
from training.torchrl_networks import load_torch_policy

__all__ = ["export_run", "main"]


def _sb3_network(run: Path) -> tuple[MLPPolicy, dict[str, Any]]:
    """The deterministic network of an SB3 ``training.train`` run (MlpPolicy, tanh) as an ``MLPPolicy``."""
    policy, config = load_learned_policy(run)
    if isinstance(policy, ResidualPolicy):  # the learned part; the header says residual
        policy = policy.correction
    model = policy.model
    net = model.policy
    if getattr(getattr(net, "mlp_extractor", None), "policy_net", None) is None or not hasattr(net, "action_net"):
        raise ValueError(f"{run}: not an actor-critic MlpPolicy ({type(net).__name__})")
    features = _sb3_slot_features(net)
    layers = [m for m in net.mlp_extractor.policy_net if isinstance(m, nn.Linear)] + [net.action_net]
    activations = {type(m) for m in net.mlp_extractor.policy_net if not isinstance(m, nn.Linear)}
    if activations - {nn.Tanh}:
        raise ValueError(f"{run}: only tanh networks can be exported, found {sorted(a.__name__ for a in activations)}")
    dim = policy.observation_dim
    if policy.normalizer is not None and policy.normalizer.norm_obs:
        if features is not None:
            raise ValueError(f"{run}: a slot network must read raw observations (normalize: {{norm_obs: false}})")
        rms = policy.normalizer.obs_rms
        mean, std = rms.mean, np.sqrt(rms.var + policy.normalizer.epsilon)
        clip = float(policy.normalizer.clip_obs)
    elif features is not None:
        mean, std, clip = np.zeros(()), np.ones(()), np.inf  # any length
    else:
        mean, std, clip = np.zeros(dim), np.ones(dim), np.inf
    weights = [m.weight.detach().double().numpy().T.copy() for m in layers]
    biases = [m.bias.detach().double().numpy().copy() for m in layers]
    return MLPPolicy(weights, biases, mean, std, clip, "clip", policy.action_dim, features), config


def _sb3_slot_features(net: Any) -> dict[str, np.ndarray] | None:
    """The weights of an SB3 policy's (actor's) ``SlotFeatures`` extractor; None for SB3's weightless flatten one."""
    extractor = net.features_extractor
    if type(extractor).__name__ != "SlotFeatures":
        if any(True for _ in extractor.parameters()):
            raise ValueError(f"cannot export a {type(extractor).__name__} features extractor")
        return None

    def linear(module: Any) -> tuple[np.ndarray, np.ndarray]:
        return module.weight.detach().double().numpy().T.copy(), module.bias.detach().double().numpy().copy()

    out: dict[str, np.ndarray] = {}
    out["message_w0"], out["message_b0"] = linear(extractor.message[0])
    out["message_w1"], out["message_b1"] = linear(extractor.message[2])
    out["own_w0"], out["own_b0"] = linear(extractor.own[0])
    if extractor.zero_at_agreement:
        out["zero_at_agreement"] = np.array(1.0)
    return out


def _torchrl_network(run: Path) -> tuple[MLPPolicy, dict[str, Any]]:
    """The deterministic network of a ``training.torchrl_ppo`` run (running norm, shared MLP, tanh) as an MLPPolicy."""
    policy, config = load_torch_policy(run)
    trunk = policy.trunk
    dim = policy.observation_dim
    inputs = str(config.get("inputs", "raw"))
    input_mask = None
    if isinstance(trunk[0], InputMask):  # drop_inputs: the mask first, then the network as without it
        input_mask, trunk = trunk[0].mask.double().numpy(), trunk[1:]
    if len(trunk) == 2 and inputs == "raw":  # a running norm, then the MLP
        norm = trunk[0]
        mean = norm.mean.double().numpy()
        std = np.sqrt(norm.var.double().numpy() + 1e-8)
        clip = 10.0
    else:  # the MLP alone, or the fixed input map (MLPPolicy's inputs="predicted") and the MLP
        mean, std, clip = np.zeros(dim), np.ones(dim), np.inf
    mlp = trunk[-1]
    # a MultiAgentMLP with shared parameters keeps them in ``params`` (keys "0", "2", ...: the Linear layers'
    # indices in its empty template network, tanh between them)
    template = mlp._empty_net
    others = {type(m) for m in template if not isinstance(m, nn.Linear)}
    if others - {nn.Tanh}:
        raise ValueError(f"{run}: only tanh networks can be exported, found {sorted(a.__name__ for a in others)}")
    indices = [str(k) for k, m in enumerate(template) if isinstance(m, nn.Linear)]
    params = mlp.params
    weights = [params[k, "weight"].detach().double().numpy().T.copy() for k in indices]
    biases = [params[k, "bias"].detach().double().numpy().copy() for k in indices]
    # the action units (action_scale) multiply the means, the last layer's first A outputs: fold them in
    units = policy.action_scale.astype(np.float64)
    weights[-1][:, : policy.action_dim] *= units
    biases[-1][: policy.action_dim] *= units
    squash = "tanh" if policy.distribution == "tanh_normal" else "clip"
    return MLPPolicy(
        weights, biases, mean, std, clip, squash, policy.action_dim, inputs=inputs, input_mask=input_mask
    ), config


def export_run(
    run: str | Path,
    name: str,
    description: str = "",
    folder: Path | None = None,
    training: dict[str, Any] | None = None,
    evaluation: dict[str, Any] | None = None,
    episodes: int = 10,
) -> Path:
    """Export the policy of a run folder (SB3 ``training.train`` or ``training.torchrl_ppo``) as ``NAME.npz``.

    The header takes the scenario, env overrides and team size from the run's
    config; ``training`` and ``evaluation`` add what the caller knows. Without
    an ``evaluation`` the run's ``evaluation.json`` is read, and if there is
    none (a run stopped before its closing evaluation), the trained network
    (the library's, not the numpy copy) and the reference are run on the first
    ``episodes`` evaluation seeds (``baselines.seeds``) of its training
    scenario: every header says what its policy scored.
    """
    run = Path(run)
    if not name.replace("_", "").isalnum():
        raise ValueError(f"a pretrained policy's name is letters, digits and underscores, got {name!r}")
    run_dir = run_folder_of(run)
    pipeline = trainer_of(run_dir)
    if pipeline not in NETWORKS:
        raise ValueError(f"{run}: only runs of {sorted(NETWORKS)} can be exported, this one is of {pipeline!r}")
    policy, config = NETWORKS[pipeline](run)
    scenario, env_kwargs = config["scenario"], dict(config["env_kwargs"])
    cfg = make_config(scenario, **env_kwargs)
    measured = dict(evaluation or {})
    summary = run_dir / "evaluation.json"
    if not measured and summary.is_file():
        measured = json.loads(summary.read_text())
    if "learned_returns" not in measured:  # no closing evaluation: measure the trained network
        measured = _measure(run, episodes)
    info = PretrainedInfo(
        name=name,
        scenario=scenario,
        env_kwargs=json.loads(json.dumps(env_kwargs)),
        action_level=cfg.action_level,
        n_vessels=None if policy.features is not None else cfg.n_vessels,
        observation_dim=policy.observation_dim,
        action_dim=policy.action_dim,
        kind="mlp" if policy.features is None else "slots",
        description=description,
        training={"pipeline": pipeline, "seed": config.get("seed"), **(training or {})},
        evaluation=measured,
        residual=bool(config.get("residual", False)),
    )
    return save_pretrained(policy, info, folder)


def _measure(run: Path, episodes: int) -> dict[str, Any]:
    """The run's policy and the reference on the first ``episodes`` evaluation seeds of its scenario."""
    policy, config = load_learned_policy(run)
    seeds = evaluation_seeds(episodes)
    return {"seeds": seeds, **evaluation_summary(policy, config["scenario"], config["env_kwargs"], seeds)}


#: The network readers of the trainers whose runs can be exported, by ``trainer`` name.
NETWORKS: dict[str, Callable[[Path], tuple[MLPPolicy, dict[str, Any]]]] = {
    "sb3": _sb3_network,
    "torchrl": _torchrl_network,
}


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m training.export", description="Export a run's policy as a pretrained .npz.")
    parser.add_argument("run", type=Path, help="a training.train or training.torchrl_ppo run folder")
    parser.add_argument("--name", required=True, help="the policy's name (letters, digits, underscores)")
    parser.add_argument("--description", default="", help="one line for --list-pretrained")
    parser.add_argument("--folder", type=Path, default=None, help="where to write (default: the shipped folder)")
    args = parser.parse_args(argv)
    try:
        path = export_run(args.run, args.name, args.description, args.folder)
    except (ValueError, FileNotFoundError) as err:
        print(f"python -m training.export: error: {err}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
