"""The TorchRL trainer's networks, and its trained policy as a batch policy.

``policy_network`` is the shared actor (one ``MultiAgentMLP`` with shared parameters for every vessel, a
Gaussian, tanh-squashed or clipped by the env) and ``critic_network`` the critic (centralized for MAPPO), each
with what the config puts before the MLP (an input mask, the fixed input map or a running norm).
``TorchPolicy`` is a trained actor's deterministic action for any number of formations and vessels;
``load_torch_policy`` reads it from a run folder's ``policy.pt``.
"""

from __future__ import annotations

import json
import pickle
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from baselines.runs import read_config, run_folder_of

__all__ = [
    "POLICY_FILE",
    "TorchPolicy",
    "actor_options",
    "critic_network",
    "load_torch_policy",
    "load_torchrl_run",
    "policy_network",
    "running_norm",
    "shared_trunk",
    "update_norm",
]

#: The policy file of a TorchRL run folder: the actor's weights and what rebuilds it.
POLICY_FILE = "policy.pt"


def running_norm(dim: int) -> Any:
    """A module ``x ↦ clip((x − mean) / sqrt(var + 1e-8), ±10)`` whose statistics are buffers.

    The statistics are pooled over every leading dimension (formations, time,
    vessels): one mean and variance per observation entry, the same for every
    vessel, so the shared weights still take any team size. They change only
    through ``update`` (parallel-variance merge of a batch, as SB3's
    ``RunningMeanStd``), never in ``forward``: the trainer updates them after
    the PPO epochs on a batch, so a batch is trained with the statistics it
    was collected with. They are saved in the module's ``state_dict``.
    """
    import torch
    from torch import nn

    class _RunningNorm(nn.Module):
        mean: torch.Tensor
        var: torch.Tensor
        count: torch.Tensor

        def __init__(self) -> None:
            super().__init__()
            self.register_buffer("mean", torch.zeros(dim))
            self.register_buffer("var", torch.ones(dim))
            self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return ((x - self.mean) / torch.sqrt(self.var + 1e-8)).clamp(-10.0, 10.0)

        @torch.no_grad()
        def update(self, x: torch.Tensor) -> None:
            flat = x.reshape(-1, dim).double()
            n_new = flat.shape[0]
            mean_new, var_new = flat.mean(0), flat.var(0, unbiased=False)
            total = self.count + n_new
            delta = mean_new - self.mean.double()
            mean = self.mean.double() + delta * (n_new / total)
            m2 = self.var.double() * self.count + var_new * n_new + delta**2 * (self.count * n_new / total)
            self.mean.copy_(mean.float())
            self.var.copy_((m2 / total).float())
            self.count.copy_(total)

    return _RunningNorm()


def actor_options(cfg: dict[str, Any]) -> dict[str, Any]:
    """The keyword arguments of ``policy_network`` that a resolved config sets (all but the sizes)."""
    return {
        "hidden": list(cfg["hidden"]),
        "normalize": bool(cfg.get("normalize_observations", False)),
        "distribution": str(cfg.get("distribution", "tanh_normal")),
        "initial_scale": float(cfg.get("initial_scale", 1.0)),
        "action_head_gain": cfg.get("action_head_gain"),
        "scale": str(cfg.get("scale", "state_dependent")),
        "action_scale": cfg.get("action_scale", 1.0),
        "inputs": str(cfg.get("inputs", "raw")),
        "dropped": list(cfg.get("drop_inputs", [])),
    }


def policy_network(
    obs_dim: int,
    action_dim: int,
    *,
    n_agents: int = 1,
    hidden: Sequence[int],
    normalize: bool = False,
    distribution: str = "tanh_normal",
    initial_scale: float = 1.0,
    action_head_gain: float | None = None,
    scale: str = "state_dependent",
    action_scale: float | Sequence[float] = 1.0,
    inputs: str = "raw",
    dropped: Sequence[str] = (),
) -> Any:
    """The shared actor: (input mask →) (input map or running norm →) ``MultiAgentMLP`` (shared) → loc, scale → the
    distribution.

    The scale is a biased softplus of the network's output, equal to ``initial_scale`` where that output is 0
    (TorchRL's ``biased_softplus``), so a freshly initialized policy explores with about that deviation.
    With ``action_head_gain`` the MLP's last layer starts with its weights scaled by it and a zero bias, so the
    first actions' means are near 0 and their deviations near ``initial_scale`` (SB3 initializes its action
    layer with gain 0.01; TorchRL's default leaves means of about ±0.1 and more on unscaled observations).
    With ``scale="state_independent"`` the network outputs the means only and the deviation is one learned
    parameter per action entry, ``exp`` of a log-deviation that starts at ``log(initial_scale)`` (SB3's Gaussian,
    TensorDict's ``AddStateIndependentNormalScale``).
    With ``action_scale`` ≠ 1 a fixed last module multiplies loc and scale by it (per action entry):
    the Gaussian over the network's units becomes one over the env's (docs/training.md, ``action_scale``).
    With ``inputs="predicted"`` the network reads ``training.inputs.PredictedInputs`` of the observation;
    with ``normalize`` its running norm (``running_norm``); with ``dropped``
    an ``training.inputs.InputMask`` of those entries first.
    """
    import math

    import torch
    from tensordict.nn import AddStateIndependentNormalScale, NormalParamExtractor, TensorDictModule
    from torch import nn
    from torchrl.modules import IndependentNormal, MultiAgentMLP, ProbabilisticActor, TanhNormal

    units = _scale_vector(action_scale, action_dim)
    rescaled = not np.all(units == 1.0)
    if rescaled and distribution != "normal":
        raise ValueError(f"action_scale {action_scale!r} needs distribution 'normal' (tanh squashes before scaling)")
    if dropped:
        from training.inputs import InputMask
    net = nn.Sequential(
        *([InputMask(obs_dim, dropped)] if dropped else []),
        *_input_modules(obs_dim, normalize, inputs),
        MultiAgentMLP(
            n_agent_inputs=obs_dim,
            n_agent_outputs=action_dim if scale == "state_independent" else 2 * action_dim,
            n_agents=n_agents,
            centralized=False,
            share_params=True,
            num_cells=list(hidden),
            activation_class=nn.Tanh,
        ),
        (
            AddStateIndependentNormalScale(action_dim, scale_mapping="exp", init_value=math.log(initial_scale))
            if scale == "state_independent"
            else NormalParamExtractor(scale_mapping=f"biased_softplus_{initial_scale}")
        ),
        *([_action_units(units)] if rescaled else []),
    )
    if action_head_gain is not None:
        *_, weight, bias = _trunk_of(net)[-1].parameters()  # the MultiAgentMLP's output layer
        with torch.no_grad():
            weight.mul_(action_head_gain)
            bias.zero_()
    module = TensorDictModule(
        net, in_keys=[("vessel", "observation")], out_keys=[("vessel", "loc"), ("vessel", "scale")]
    )
    if distribution == "normal":  # SB3's: unbounded samples, the env clips them
        kind: dict[str, Any] = {"distribution_class": IndependentNormal}
    else:
        kind = {
            "distribution_class": TanhNormal,
            "distribution_kwargs": {"low": torch.tensor(-1.0), "high": torch.tensor(1.0)},
        }
    return ProbabilisticActor(
        module,
        in_keys=[("vessel", "loc"), ("vessel", "scale")],
        out_keys=[("vessel", "action")],
        return_log_prob=True,
        **kind,
    )


def _scale_vector(action_scale: float | Sequence[float], action_dim: int) -> np.ndarray:
    """``action_scale`` as ``(action_dim,)`` float32 (one number: the same for every entry)."""
    return np.broadcast_to(np.asarray(action_scale, dtype=np.float32), (action_dim,)).copy()


def _action_units(units: np.ndarray) -> Any:
    """The module ``(loc, scale) ↦ (k·loc, k·scale)`` with the fixed ``k = units`` (a buffer, not learned)."""
    import torch
    from torch import nn

    class ActionUnits(nn.Module):
        k: torch.Tensor

        def __init__(self) -> None:
            super().__init__()
            self.register_buffer("k", torch.as_tensor(units))

        def forward(self, pair: tuple[torch.Tensor, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
            loc, scale = pair
            return loc * self.k, scale * self.k

    return ActionUnits()


def _input_modules(obs_dim: int, normalize: bool, inputs: str) -> list[Any]:
    """What a network puts before its MLP: the running norm, the fixed input map
    (``inputs: predicted``), or nothing."""
    if inputs == "predicted":
        from training.inputs import PredictedInputs

        return [PredictedInputs()]
    return [running_norm(obs_dim)] if normalize else []


def critic_network(
    obs_dim: int,
    *,
    n_agents: int,
    hidden: Sequence[int],
    centralized: bool,
    normalize: bool = False,
    inputs: str = "raw",
) -> Any:
    """The critic: (input map or running norm →) ``MultiAgentMLP`` (shared; ``centralized``: every vessel's
    observation, MAPPO) → one value per vessel."""
    from tensordict.nn import TensorDictModule
    from torch import nn
    from torchrl.modules import MultiAgentMLP

    net = nn.Sequential(
        *_input_modules(obs_dim, normalize, inputs),
        MultiAgentMLP(
            n_agent_inputs=obs_dim,
            n_agent_outputs=1,
            n_agents=n_agents,
            centralized=centralized,
            share_params=True,
            num_cells=list(hidden),
            activation_class=nn.Tanh,
        ),
    )
    return TensorDictModule(net, in_keys=[("vessel", "observation")], out_keys=[("vessel", "state_value")])


class TorchPolicy:
    """A trained TorchRL policy as a batch policy (``baselines``): deterministic, the squashed mean.

    ``act_batch((..., dim)) -> (..., A)``: every vessel acts from its own
    observation with the shared weights, so the number of formations and
    vessels in the batch is free.

    Attributes:
        observation_dim, action_dim: the sizes it was trained with.
    """

    def __init__(
        self,
        actor: Any,
        observation_dim: int,
        action_dim: int,
        *,
        distribution: str = "tanh_normal",
        action_scale: float | Sequence[float] = 1.0,
    ) -> None:
        self.actor = actor
        self.trunk = shared_trunk(actor)
        self.observation_dim = observation_dim
        self.action_dim = action_dim
        self.distribution = distribution
        #: ``(action_dim,)``: the env's action per unit of the network's mean (``action_scale``)
        self.action_scale = _scale_vector(action_scale, action_dim)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        import torch

        # every vessel is one batch entry of a one-agent MLP (the weights are shared: any team size)
        flat = torch.as_tensor(np.asarray(obs, dtype=np.float32).reshape(-1, 1, obs.shape[-1]))
        with torch.no_grad():
            # the means are the first A outputs (then the scale's, unless the scale is state-independent)
            loc = self.trunk(flat)[..., : self.action_dim] * torch.as_tensor(self.action_scale)
        action = torch.tanh(loc) if self.distribution == "tanh_normal" else loc.clamp(-1.0, 1.0)
        return np.asarray(action.numpy(), dtype=np.float32).reshape(*obs.shape[:-1], self.action_dim)

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The PettingZoo-dict form of ``act_batch``."""
        agents = list(observations)
        actions = self.act_batch(np.stack([observations[a] for a in agents]))
        return dict(zip(agents, actions, strict=True))


def load_torch_policy(folder: str | Path) -> tuple[TorchPolicy, dict[str, Any]]:
    """The policy of a ``training.torchrl_ppo`` run folder and the run's resolved config.

    Raises:
        FileNotFoundError: no ``policy.pt`` in the folder.
        ValueError: the file is not a readable policy of this trainer.
    """
    import torch

    path = Path(folder) / POLICY_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist (not a training.torchrl_ppo run folder)")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
        dims = saved["dims"]
        config = json.loads(saved["config"])
        # the shared MLP takes any number of agents: build it for one, each vessel is a batch entry; the head's
        # initial gain does not matter, the weights are loaded
        options = {**actor_options(config), "action_head_gain": None}
        actor = policy_network(int(dims["observation"]), int(dims["action"]), n_agents=1, **options)
        actor.load_state_dict(saved["actor"])
    except (KeyError, RuntimeError, ValueError, TypeError, EOFError, pickle.UnpicklingError) as err:
        raise ValueError(f"cannot load the policy {str(path)!r}: {type(err).__name__}: {err}") from err
    return (
        TorchPolicy(
            actor,
            int(dims["observation"]),
            int(dims["action"]),
            distribution=options["distribution"],
            action_scale=options["action_scale"],
        ),
        config,
    )


def load_torchrl_run(run: Path, deterministic: bool = True) -> tuple[TorchPolicy, dict[str, Any]]:
    """The policy of a ``training.torchrl_ppo`` run folder and the run's ``config.yaml``.

    The loader of the ``torchrl`` entry point of ``marine_formation_env.trainers``. The policy acts
    deterministically (the Gaussian's mean, squashed or clipped as in training).

    Raises:
        ValueError: ``deterministic`` is false, or ``policy.pt`` is not a readable policy of this trainer.
    """
    run = run_folder_of(run)
    if not deterministic:
        raise ValueError(f"the policy of the TorchRL run {str(run)!r} acts deterministically only")
    policy, _ = load_torch_policy(run)
    return policy, read_config(run)


def update_norm(net: Any, observations: Any) -> None:
    """Merge a batch into the running norm of a network's ``nn.Sequential``, as the modules before it (an input
    mask) hand it on."""
    import torch

    seen = observations
    with torch.no_grad():
        for module in net:
            if hasattr(module, "update"):
                module.update(seen)
                return
            seen = module(seen)
    raise ValueError(f"no running norm in {[type(module).__name__ for module in net]}")


def shared_trunk(actor: Any) -> Any:
    """The observation → network-output part of an actor built by ``policy_network``: its input mask and
    running norm (each if any) and its ``MultiAgentMLP``, without the ``NormalParamExtractor`` (and the action
    units, if any)."""
    return _trunk_of(actor.module[0].module)


def _trunk_of(net: Any) -> Any:
    """The modules of ``policy_network``'s ``nn.Sequential`` up to and including its ``MultiAgentMLP``."""
    from torchrl.modules import MultiAgentMLP

    found = [k for k, module in enumerate(net) if isinstance(module, MultiAgentMLP)]
    if len(found) != 1:
        kinds = [type(module).__name__ for module in net]
        raise ValueError(f"not an actor of training.torchrl_ppo: expected one MultiAgentMLP, found {kinds}")
    return net[: found[0] + 1]
