"""Pretrained policies shipped with the project, runnable with numpy alone.

Each policy is one file, ``baselines/pretrained/NAME.npz``: the weights of its
network as numpy arrays and a JSON header (``meta``) saying what it expects
(scenario, env overrides, action level, team size, observation layout) and
how it was trained and measured. No torch, SB3 or TorchRL is needed to run
one::

    from baselines.pretrained import load_pretrained
    policy, info = load_pretrained("paper_speed")
    env = marine_formation_env.parallel_env(info.scenario, **info.env_kwargs)
    observations, _ = env.reset(seed=0)
    actions = policy.act(observations)

and from the command line, next to the reference::

    python -m baselines.evaluate --policy pretrained:paper_speed --policy reference --episodes 10
    python -m baselines.evaluate --list-pretrained

A policy takes another scenario with the same observation layout and action
level (that is how generalization is measured: ``--scenario acoustic`` with
``pretrained:paper_speed``); a team size, action level or layout it cannot
take is refused by ``check_compatible``, naming both sides.

Two network kinds:

``mlp``
    ``obs → (obs − mean) / std, clipped to ±clip → [Linear → tanh]* → Linear → squash``,
    the observation statistics of SB3's ``VecNormalize`` or of
    ``training.torchrl_ppo``'s running norm folded in; ``squash`` is ``clip``
    (SB3's deterministic action, the Gaussian's mean clipped to the action
    space) or ``tanh`` (TorchRL's tanh-squashed Gaussian's mode). It exists
    for one team size. A file may add ``inputs`` (a fixed input map first:
    ``predicted_inputs``) or ``input_mask`` (entries the network does not
    read, zeroed first: ``training.torchrl_ppo``'s ``drop_inputs``).
``slots``
    the same, after a graph network over the observation's slots
    (``slot_features``, ``training.slot_policy``): it takes any number
    of slots, so any team size.

Files are written atomically by ``save_pretrained``; ``training.export``
makes one from a run folder (``python -m training.export RUN --name NAME``).
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baselines.reference import predicted_coordination_error
from baselines.residual import ResidualPolicy
from baselines.rollout import BatchPolicy
from marine_formation_env import ENV_ID
from marine_formation_env.atomic import atomic_write_bytes
from marine_formation_env.cli import ArgumentParser
from marine_formation_env.rules import (
    COORDINATION,
    CURVATURE,
    LANE_OFFSET,
    OWN_SIZE,
    SLOT_SIZE,
    slot_count,
    traffic_entries,
)
from marine_formation_env.scenarios import ScenarioConfig, make_config

__all__ = [
    "FORMAT",
    "PRETRAINED_DIR",
    "MLPPolicy",
    "PretrainedInfo",
    "check_compatible",
    "list_pretrained",
    "load_pretrained",
    "save_pretrained",
]

#: Where the shipped policies live.
PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"
#: Version of the file format (the header's ``format``).
FORMAT = 1
KINDS = ("mlp", "slots")
SQUASHES = ("clip", "tanh")
#: What an ``MLPPolicy`` reads: the observation itself, or ``predicted_inputs`` of it.
INPUTS = ("raw", "predicted")


@dataclass(frozen=True)
class PretrainedInfo:
    """What a pretrained policy expects and how it came about (the file's JSON header).

    Attributes:
        name: the policy's name (its file's stem).
        scenario, env_kwargs: what it was trained on; the default of an evaluation.
        action_level: ``force``, ``guidance`` or ``speed``.
        n_vessels: the team size it takes, or None (any).
        observation_dim: the length of the observation it takes (None: any team size).
        action_dim: the length of its action.
        env_id: the env version whose observation layout it was trained on.
        kind: ``mlp`` (one team size) or ``slots`` (any team size).
        description: one line for ``--list-pretrained``.
        training: how it was trained (pipeline, seed, minutes, vessel-steps, commit, config).
        evaluation: what it measured at export (return, success, reference's return, seeds).
        residual: the network is the learned part of a residual policy (``baselines.residual``): the policy
            acts with the extrapolating reference's action plus the network's output, gated to vanish in
            formation.
    """

    name: str
    scenario: str
    env_kwargs: dict[str, Any]
    action_level: str
    n_vessels: int | None
    observation_dim: int | None
    action_dim: int
    env_id: str = ENV_ID
    kind: str = "mlp"
    description: str = ""
    training: dict[str, Any] = field(default_factory=dict)
    evaluation: dict[str, Any] = field(default_factory=dict)
    residual: bool = False

    def to_json(self) -> str:
        return json.dumps({"format": FORMAT, **self.__dict__}, sort_keys=True)


class MLPPolicy(BatchPolicy):
    """A deterministic tanh MLP over one vessel's observation (every vessel, shared weights).

    Args:
        weights: layer ``k`` maps ``x ↦ x @ weights[k] + biases[k]``; tanh between layers.
        biases: the layers' biases (above).
        mean: the observation normalization ``clip((obs − mean) / std, ±clip)``: its mean,
        std: its deviation,
        clip: and its bound.
        squash: ``clip`` (to [−1, 1]) or ``tanh``, applied to the first ``action_dim`` outputs.
        features: the weights of ``slot_features`` (a ``slots`` network: any number of slots), or None.
        inputs: ``raw``, or ``predicted``: the network reads ``predicted_inputs`` of the observation (before
            the normalization above; ``training.torchrl_ppo``'s ``inputs: predicted``).
        input_mask: ``(observation_dim,)`` of 0 and 1 multiplying the observation before everything else (0: an
            entry the network does not read; ``training.torchrl_ppo``'s ``drop_inputs``), or None.
    """

    def __init__(
        self,
        weights: Sequence[np.ndarray],
        biases: Sequence[np.ndarray],
        mean: np.ndarray,
        std: np.ndarray,
        clip: float,
        squash: str,
        action_dim: int,
        features: dict[str, np.ndarray] | None = None,
        inputs: str = "raw",
        input_mask: np.ndarray | None = None,
    ) -> None:
        if squash not in SQUASHES:
            raise ValueError(f"squash must be one of {list(SQUASHES)}, got {squash!r}")
        if inputs not in INPUTS:
            raise ValueError(f"inputs must be one of {list(INPUTS)}, got {inputs!r}")
        self.inputs = inputs
        self.weights = [np.asarray(w, dtype=np.float64) for w in weights]
        self.biases = [np.asarray(b, dtype=np.float64) for b in biases]
        self.mean = np.asarray(mean, dtype=np.float64)
        self.std = np.asarray(std, dtype=np.float64)
        self.clip = float(clip)
        self.squash = squash
        self.features = None if features is None else _checked_features(features)
        #: the observation length it takes (None: any 10 + 4·slots, a ``slots`` network)
        self.observation_dim: int | None = int(self.weights[0].shape[0]) if features is None else None
        self.input_mask = None if input_mask is None else np.asarray(input_mask, dtype=np.float64)
        if self.input_mask is not None and self.observation_dim is None:
            raise ValueError("input_mask applies to an MLP of one observation size, not to a slots network")
        if self.input_mask is not None and (
            self.input_mask.shape != (self.observation_dim,) or not np.all(np.isin(self.input_mask, (0.0, 1.0)))
        ):
            raise ValueError(
                f"input_mask must be {self.observation_dim} zeros and ones (an MLP's inputs), got {input_mask!r}"
            )
        self.action_dim = int(action_dim)
        #: the header of the file it was loaded from (``load_pretrained``), else None
        self.info: PretrainedInfo | None = None

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        if self.observation_dim is not None and obs.shape[-1] != self.observation_dim:
            raise ValueError(f"observations of size {obs.shape[-1]} given, this policy takes {self.observation_dim}")
        if self.input_mask is not None:
            obs = obs * self.input_mask
        if self.inputs == "predicted":
            obs = predicted_inputs(obs)
        x = np.clip((obs - self.mean) / self.std, -self.clip, self.clip)
        if self.features is not None:
            x = slot_features(x, self.features)
        for k, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = x @ w + b
            if k < len(self.weights) - 1:
                x = np.tanh(x)
        out = x[..., : self.action_dim]
        out = np.tanh(out) if self.squash == "tanh" else np.clip(out, -1.0, 1.0)
        return out.astype(np.float32)

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays of its file."""
        out = {"mean": self.mean, "std": self.std, "clip": np.array(self.clip), "squash": np.array(self.squash)}
        if self.inputs != "raw":  # files of raw-input policies stay as they were
            out["inputs"] = np.array(self.inputs)
        if self.input_mask is not None:  # and files of policies that read every entry
            out["input_mask"] = self.input_mask
        for k, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            out[f"w{k}"], out[f"b{k}"] = w, b
        for name, value in (self.features or {}).items():
            out[f"features_{name}"] = value
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], action_dim: int) -> MLPPolicy:
        layers = sum(1 for key in arrays if key.startswith("w"))
        features = {key[len("features_") :]: value for key, value in arrays.items() if key.startswith("features_")}
        return cls(
            [arrays[f"w{k}"] for k in range(layers)],
            [arrays[f"b{k}"] for k in range(layers)],
            arrays["mean"],
            arrays["std"],
            float(arrays["clip"]),
            str(arrays["squash"]),
            action_dim,
            features or None,
            str(arrays["inputs"]) if "inputs" in arrays else "raw",
            arrays.get("input_mask"),
        )


#: Fixed scales of the own entries of a slot network (``training.slot_policy``): e [m], ψ [rad], u, v [m/s],
#: r [rad/s], u_d [m/s], u̇_d [m/s²], κ, κ ahead [1/m], and κ·D_y in place of the lane offset D_y (see
#: ``own_inputs``).
OWN_SCALE = np.array([50.0, 1.0, 5.0, 1.0, 0.1, 5.0, 0.1, 1.0 / 300.0, 1.0 / 300.0, 0.1])
#: Fixed scales of a slot's entries (link bit, θ_j − θ_i [m], ẋ_j − ẋ_i [m/s], age [s]).
SLOT_SCALE = np.array([1.0, 50.0, 2.0, 10.0])
#: ``predicted_inputs``' scales of ``TRANSMIT_FEATURES``: the budget's share as it is, seconds by 10 as ages,
#: the prediction drift in metres as it is.
TRAFFIC_SCALE = np.array([1.0, 10.0, 1.0])
#: A slot network's slot inputs (link bit, Δθ, Δẋ, age) as a neighbour in agreement has them, by
#: multiplication: Δθ = Δẋ = 0, the link bit and the age kept (``zero_at_agreement``).
AGREEMENT_MASK = np.array([1.0, 0.0, 0.0, 1.0])


def own_inputs(own: np.ndarray) -> np.ndarray:
    """A slot network's own inputs: the own part (``(..., OWN_SIZE)``) with the lane offset D_y replaced by
    κ·D_y, divided by ``OWN_SCALE``.

    The lane offset grows with the team (the paper's lanes, 50 m apart, span −450 to 500 m at n = 20 and
    −100 to 150 m at n = 6), so read raw it is an input no training team shows, and it biases each vessel's speed by its
    lane: the first any-team policy held a steady spread of 1.3 m at n = 8 and 33 m at n = 20 (chain), and
    settled when D_y was zeroed (docs/results.md). The curved-path law needs D_y only through κ·D_y
    (u_c = (1 − κ·D_y)·w), which is 0 on a straight path whatever the team.
    ``training.slot_policy.SlotFeatures`` does the same in torch.
    """
    out = np.array(own, dtype=np.float64)
    out[..., LANE_OFFSET] = out[..., CURVATURE] * out[..., LANE_OFFSET]
    return out / OWN_SCALE


def own_and_slots(obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The own inputs ``(..., OWN_SIZE)`` and the slots ``(..., K, SLOT_SIZE)`` of ``predicted_inputs``
    (``training.inputs.own_and_slots`` is the same map in torch)."""
    obs = np.asarray(obs, dtype=np.float64)
    k = slot_count(obs.shape[-1])
    own = obs[..., :OWN_SIZE]
    slots = obs[..., OWN_SIZE:].reshape(*obs.shape[:-1], k, SLOT_SIZE).copy()
    slots[..., COORDINATION] = predicted_coordination_error(own, slots)  # Δθ predicted to now (unchanged at age 0)
    return own_inputs(own), slots / SLOT_SCALE


def predicted_inputs(obs: np.ndarray) -> np.ndarray:
    """The slot network's fixed input map, keeping the observation's layout ``(..., dim) → (..., dim)``.

    Each slot's Δθ predicted to now from the message's velocity and age (as ``reference:extrapolate``),
    κ·D_y for the lane offset (``own_inputs``), every entry divided by ``OWN_SCALE`` or
    ``SLOT_SCALE``; with ``transmit`` the last entries (``TRANSMIT_FEATURES``) divided by
    ``TRAFFIC_SCALE``. ``training.inputs.PredictedInputs`` is the same map in torch
    (``training.torchrl_ppo``'s ``inputs: predicted``).
    """
    obs = np.asarray(obs, dtype=np.float64)
    traffic = traffic_entries(obs.shape[-1])
    own, slots = own_and_slots(obs[..., : obs.shape[-1] - traffic])
    parts = [own, slots.reshape(*slots.shape[:-2], -1)]
    if traffic:
        parts.append(obs[..., -traffic:] / TRAFFIC_SCALE)
    return np.concatenate(parts, axis=-1)


#: The arrays every ``slot_features`` weights dict holds,
SLOT_WEIGHTS = ("message_w0", "message_b0", "message_w1", "message_b1", "own_w0", "own_b0")
#: and the one an option adds (``SlotFeatures(zero_at_agreement=True)``).
SLOT_OPTIONS = ("zero_at_agreement",)


def _checked_features(features: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``slot_features``' weights as float64 arrays, or a ValueError naming what is missing, unknown or bad."""
    out = {k: np.asarray(v, dtype=np.float64) for k, v in features.items()}
    missing = [k for k in SLOT_WEIGHTS if k not in out]
    unknown = [k for k in out if k not in SLOT_WEIGHTS + SLOT_OPTIONS]
    if missing or unknown:
        raise ValueError(f"slot network weights: missing {missing}, unknown {unknown}")
    if "zero_at_agreement" in out and not (out["zero_at_agreement"].shape == () and out["zero_at_agreement"] == 1.0):
        raise ValueError(
            f"slot network weights: zero_at_agreement must be 1 if present, got {out['zero_at_agreement']!r}"
        )
    return out


def _message(pairs: np.ndarray, weights: dict[str, np.ndarray]) -> np.ndarray:
    """The message network φ of ``slot_features`` (two tanh layers) on ``[own, slot]`` pairs."""
    h = np.tanh(pairs @ weights["message_w0"] + weights["message_b0"])
    return np.tanh(h @ weights["message_w1"] + weights["message_b1"])


def slot_features(obs: np.ndarray, weights: dict[str, np.ndarray]) -> np.ndarray:
    """``training.slot_policy.SlotFeatures`` in numpy (float64); ``weights``: ``{name: array}``, layers ``x @ w + b``.

    ``weights`` holds ``message_w0, message_b0, message_w1, message_b1, own_w0, own_b0``, and
    ``zero_at_agreement`` (1) if each message is measured from that of a neighbour with Δθ = Δẋ = 0
    (``SlotFeatures(zero_at_agreement=True)``). With ``transmit`` (``TRANSMIT_FEATURES`` after the slots)
    ψ reads them too, divided by ``TRAFFIC_SCALE``: ``own_w0`` then has ``OWN_SIZE + 3`` rows.

    Raises:
        ValueError: ``own_w0``'s rows do not match the observation's own part (and traffic entries).
    """
    obs = np.asarray(obs, dtype=np.float64)
    traffic = traffic_entries(obs.shape[-1])
    rows = weights["own_w0"].shape[0]
    if rows != OWN_SIZE + traffic:
        raise ValueError(
            f"the slot network reads {rows} own inputs, this observation of size {obs.shape[-1]} has"
            f" {OWN_SIZE} + {traffic} (transmit entries)"
        )
    own, slots = own_and_slots(obs[..., : obs.shape[-1] - traffic])
    heard = (slots[..., :1] > 0.5).astype(np.float64)
    own_k = np.broadcast_to(own[..., None, :], (*slots.shape[:-1], own.shape[-1]))
    messages = _message(np.concatenate([own_k, slots], axis=-1), weights)
    if "zero_at_agreement" in weights:  # minus the message of a neighbour that agrees
        agreed = slots * AGREEMENT_MASK
        messages = messages - _message(np.concatenate([own_k, agreed], axis=-1), weights)
    messages = messages * heard
    total = messages.sum(axis=-2)
    mean = total / np.maximum(heard.sum(axis=-2), 1.0)
    if traffic:
        own = np.concatenate([own, obs[..., -traffic:] / TRAFFIC_SCALE], axis=-1)
    return np.concatenate([np.tanh(own @ weights["own_w0"] + weights["own_b0"]), total, mean], axis=-1)


# ----------------------------------------------------------------------------- files


def _path(name: str, folder: Path | None = None) -> Path:
    return (folder or PRETRAINED_DIR) / f"{name}.npz"


def save_pretrained(policy: MLPPolicy, info: PretrainedInfo, folder: Path | None = None) -> Path:
    """Write ``policy`` and ``info`` to ``folder/NAME.npz`` atomically; returns the path."""
    if info.kind not in KINDS:
        raise ValueError(f"kind must be one of {list(KINDS)}, got {info.kind!r}")
    target = _path(info.name, folder)
    target.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    arrays: dict[str, Any] = {"meta": np.array(info.to_json()), **policy.arrays()}
    np.savez_compressed(buffer, **arrays)
    atomic_write_bytes(target, buffer.getvalue())
    return target


def _read(path: Path) -> tuple[MLPPolicy, PretrainedInfo]:
    """The policy and header of one file (``ValueError`` naming the file if it is not a readable one)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
        header = json.loads(str(arrays.pop("meta")))
        version = header.pop("format")
        if version != FORMAT:
            raise ValueError(f"file format {version}, this version reads {FORMAT}")
        info = PretrainedInfo(**header)
        policy = MLPPolicy.from_arrays(arrays, info.action_dim)
    except (OSError, EOFError, zipfile.BadZipFile, KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{path} is not a readable pretrained policy ({type(err).__name__}: {err})") from None
    policy.info = info
    return policy, info


def list_pretrained(folder: Path | None = None) -> list[PretrainedInfo]:
    """The headers of every policy in ``folder`` (default: the shipped ones), sorted by name."""
    return [_read(path)[1] for path in sorted((folder or PRETRAINED_DIR).glob("*.npz"))]


def load_pretrained(name: str, folder: Path | None = None) -> tuple[BatchPolicy, PretrainedInfo]:
    """The policy called ``name`` and its header.

    The policy is the file's network (``MLPPolicy``), or, for a file whose header says ``residual``, the
    ``ResidualPolicy`` of that network on the policy's training configuration.

    Raises:
        ValueError: no such policy (the message lists the shipped ones) or an unreadable file.
    """
    path = _path(name, folder)
    if not path.is_file():
        known = [info.name for info in list_pretrained(folder)]
        raise ValueError(f"no pretrained policy {name!r}; shipped: {known}")
    network, info = _read(path)
    if not info.residual:
        return network, info
    policy = ResidualPolicy(network, make_config(info.scenario, **info.env_kwargs))
    policy.info = info
    return policy, info


def check_compatible(info: PretrainedInfo, config: ScenarioConfig, observation_dim: int) -> None:
    """Refuse (``ValueError``) a scenario whose team size, action level or observation layout ``info`` cannot take.

    Another scenario with the same layout and level is accepted: that is a generalization test.
    """
    where = f"pretrained policy {info.name!r} (trained on {info.scenario!r}"
    if info.env_id != ENV_ID:
        raise ValueError(f"{where} with {info.env_id}) reads another observation layout than {ENV_ID}")
    if info.action_level != config.action_level:
        raise ValueError(
            f"{where}) acts at action_level {info.action_level!r}, this scenario has {config.action_level!r}; "
            f"pass --set action_level={info.action_level}"
        )
    trained_transmit = bool(info.env_kwargs.get("transmit", False))
    if trained_transmit != config.transmit:
        sends = "sends" if trained_transmit else "does not send"
        raise ValueError(
            f"{where}) {sends} the transmit action, this scenario has transmit={config.transmit}; "
            f"pass --set transmit={trained_transmit}"
        )
    if info.n_vessels is not None and info.n_vessels != config.n_vessels:
        raise ValueError(
            f"{where}) takes teams of {info.n_vessels} vessels, this scenario has n_vessels = {config.n_vessels}"
        )
    if info.observation_dim is not None and info.observation_dim != observation_dim:
        raise ValueError(
            f"{where}) takes observations of size {info.observation_dim}, this scenario gives {observation_dim}"
        )


# ----------------------------------------------------------------------------- command line


def format_listing(infos: Sequence[PretrainedInfo]) -> str:
    """The table of ``baselines.evaluate --list-pretrained``."""
    rows = [["name", "scenario", "level", "vessels", "pipeline", "return (reference)", "success", "description"]]
    for info in infos:
        ev = info.evaluation
        ret = (
            f"{ev['learned_return']:.1f} ({ev['reference_return']:.1f})"
            if "learned_return" in ev and "reference_return" in ev
            else "-"
        )
        success = f"{ev['learned_success']:.0%}" if "learned_success" in ev else "-"
        rows.append(
            [
                info.name,
                info.scenario,
                info.action_level,
                "any" if info.n_vessels is None else str(info.n_vessels),
                str(info.training.get("pipeline", "-")),
                ret,
                success,
                info.description,
            ]
        )
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip() for row in rows)


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m baselines.pretrained", description="List the shipped pretrained policies.")
    parser.parse_args(argv)
    print(format_listing(list_pretrained()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
