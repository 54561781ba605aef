"""What every front end does the same way: ``reset`` arguments, infos and rendering.

The PettingZoo env, the gymnasium view and the vector env accept the same
``reset(seed=…, options=…)`` and refuse the same bad input with the same
message, report their infos in one schema, and render through one piece of
code. This module holds those rules once; the front ends only lay them out.

Infos (the same keys from ``reset()``, with zeros, as from ``step()``). They
are flat, one number (or array) per key, because wrappers such as TorchRL's
``PettingZooWrapper`` turn every info entry into a tensor; the reward terms
are ``reward_<term>`` (``REWARD_INFO_KEYS``, read back by name with
``reward_terms``):

* **per vessel** (ParallelEnv ``infos[agent]``, vector env ``layout="agent"``
  entries): ``reward_cross_track``, ``reward_heading``, ``reward_coordination``,
  ``reward_speed``, ``reward_effort``, ``reward_terminal``,
  ``reward_communication`` (that vessel's terms; they sum to its reward),
  ``time`` [s], ``collision``, ``out_of_bounds`` (the formation's flags),
  ``commanded_speed`` u_c [m/s] at the ``speed`` and ``guidance`` levels, and
  the messages of the control instant (``MESSAGE_KEYS``, whole numbers):
  ``messages_attempted``, ``messages_sent``, ``messages_delivered``,
  ``messages_dropped_loss``, ``messages_dropped_range``,
  ``messages_dropped_schedule``, ``messages_dropped_budget`` and
  ``bits_sent`` (``marine_formation_env.channel`` defines each).
* **per formation** (``gymnasium.make`` info, vector env ``layout="joint"``
  entries): ``vessel_rewards`` ``(N,)``, the ``reward_<term>`` entries (the
  mean over the vessels; they sum to the formation's reward, the mean of the
  vessels'), ``time``, ``collision``, ``out_of_bounds``,
  ``commanded_speed`` ``(N,)``, and the message counters summed over the
  vessels.

The vector env stacks these over its entries (arrays with a leading
``num_envs`` axis); the single-formation views hold plain Python numbers.

Reset options (all optional):

* ``initial_state``: ``(n, 6)`` array, columns ``x, y, psi, u, v, r``; the
  vector env also takes ``(B, n, 6)``. It must be finite and must not end the
  episode at its first step (``initial_state_problem``).
* ``channel_seed``: a whole number ≥ 0 that seeds the channel stream on its
  own (the vector env also takes a list of B of them).

``options`` that is not a mapping raises ``TypeError``. Any other key is
ignored with a ``UserWarning`` that names it, by every front end alike (an
option silently ignored is an experiment silently not run, but PettingZoo's
own ``parallel_api_test`` passes an unknown option and expects it accepted).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from marine_formation_env.core import COLUMNS_HINT, MESSAGE_KEYS, REWARD_COMPONENTS, FormationCore, StepOutput
from marine_formation_env.errors import check_seed, checked_array
from marine_formation_env.render import check_render_mode, render_fps
from marine_formation_env.scenarios import (
    ScenarioConfig,
    initial_state_problem,
    make_config,
    sample_initial_states,
    spread_config,
)

__all__ = [
    "RESET_OPTIONS",
    "REWARD_INFO_KEYS",
    "InitialStates",
    "Rendering",
    "ResetRequest",
    "action_size_hint",
    "check_initial_state",
    "check_reset_options",
    "formation_infos",
    "formation_seeds",
    "one_entry",
    "open_front_end",
    "read_reset",
    "resolve_config",
    "reward_terms",
    "vessel_infos",
    "vessel_mean",
]

#: The info keys of the reward terms, in the order of ``REWARD_COMPONENTS``: ``reward_cross_track``, ...
REWARD_INFO_KEYS = tuple(f"reward_{name}" for name in REWARD_COMPONENTS)

#: The keys ``reset(options=…)`` understands.
RESET_OPTIONS = ("initial_state", "channel_seed")


def resolve_config(scenario: str | ScenarioConfig, overrides: Mapping[str, Any]) -> ScenarioConfig:
    """The configuration a front end runs: a scenario name with overrides, or a ready ``ScenarioConfig``.

    Raises:
        ConfigError: unknown scenario or override (``make_config``).
        TypeError: overrides given together with a ready configuration.
    """
    if isinstance(scenario, ScenarioConfig):
        if overrides:
            raise TypeError(
                f"overrides {sorted(overrides)} cannot be applied to a ready ScenarioConfig; pass a scenario name, "
                "or build the configuration with make_config(name, **overrides)"
            )
        return scenario
    return make_config(scenario, **overrides)


def open_front_end(
    metadata: Mapping[str, Any],
    scenario: str | ScenarioConfig,
    overrides: Mapping[str, Any],
    render_mode: str | None,
    render_speedup: float,
    backend: str,
    num_envs: int = 1,
) -> tuple[ScenarioConfig, dict[str, Any], FormationCore]:
    """What every front end's constructor does first: check ``render_mode`` against ``metadata["render_modes"]``,
    resolve the configuration (``resolve_config``), set ``render_fps`` for it (``render_speedup``), then build
    the core. Returns the configuration, the instance's metadata (a copy of ``metadata`` with ``render_fps``) and
    the core.

    Raises:
        ValueError: unknown render mode.
        ConfigError: unknown scenario or override, or ``render_speedup`` not a finite number > 0.
        TypeError: overrides given together with a ready configuration.
    """
    check_render_mode(render_mode, metadata["render_modes"])
    config = resolve_config(scenario, overrides)
    instance_metadata = {**metadata, "render_fps": render_fps(config.dt, render_speedup)}
    return config, instance_metadata, FormationCore(config, num_envs=num_envs, backend=backend)


def check_reset_options(options: Any) -> dict[str, Any]:
    """``options`` as a dict of the known keys; ``TypeError`` if it is not a mapping.

    Unknown keys are dropped with a ``UserWarning`` that names them.
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"reset options must be a dict (or None), got {options!r} ({type(options).__name__})")
    unknown = sorted(map(repr, set(options) - set(RESET_OPTIONS)))
    if unknown:
        warnings.warn(
            f"reset ignores unknown option(s) [{', '.join(unknown)}]; known options: {list(RESET_OPTIONS)}",
            UserWarning,
            stacklevel=3,
        )
    return {key: options[key] for key in RESET_OPTIONS if key in options}


def check_initial_state(config: ScenarioConfig, value: Any, batch: int | None = None) -> np.ndarray:
    """A float64 initial state ``(n, 6)`` (or ``(batch, n, 6)`` when ``batch`` is given) from ``options``.

    Raises:
        TypeError: not numeric.
        ValueError: wrong shape, a non-finite entry, or a state that would
            end the episode at its first step (names the vessel and the bound).
    """
    n = config.n_vessels
    shapes = [(n, 6)] + ([] if batch is None else [(batch, n, 6)])
    arr = checked_array(value, "initial_state", shapes, hint=COLUMNS_HINT)
    for b, state in enumerate(arr.reshape(-1, n, 6)):
        problem = initial_state_problem(config, state)
        if problem is not None:
            where = f"initial_state[{b}]" if arr.ndim == 3 else "initial_state"
            raise ValueError(f"{where}: {problem}")
    return arr


def formation_seeds(seed: Any, num_formations: int, name: str = "seed") -> list[int | None]:
    """One seed per formation: ``seed + b`` for a whole number, or a list of ``num_formations`` seeds.

    Python and numpy integers are accepted; floats, strings and booleans are
    refused (``TypeError``) and so are negative seeds (``ValueError``), with
    the offending entry named.
    """
    if seed is None:
        return [None] * num_formations
    if isinstance(seed, (list, tuple, np.ndarray)):
        seeds = list(seed)
        if len(seeds) != num_formations:
            raise ValueError(
                f"{name} needs a whole number or a list of {num_formations} seeds (one per formation), got {seed!r}"
            )
        return [check_seed(s, f"{name}[{b}]") for b, s in enumerate(seeds)]
    first = check_seed(seed, name)
    assert first is not None
    return [first + b for b in range(num_formations)]


@dataclass(frozen=True)
class ResetRequest:
    """The checked arguments of one ``reset(seed=…, options=…)`` call.

    Attributes:
        seeds: one per formation (None: keep that formation's generator).
        channel_seeds: one per formation, for the channel streams (the reset
            seeds unless ``options["channel_seed"]`` is given).
        initial_state: the state to set exactly, ``(n, 6)`` or ``(B, n, 6)``,
            or None to draw it from the scenario's initial-state noise.
    """

    seeds: list[int | None]
    channel_seeds: list[int | None]
    initial_state: np.ndarray | None


def read_reset(config: ScenarioConfig, seed: Any, options: Any, num_formations: int | None = None) -> ResetRequest:
    """Check every ``reset`` argument before anything changes, the same way for every front end.

    Args:
        config: the front end's configuration.
        seed: as passed to ``reset``.
        options: as passed to ``reset``.
        num_formations: None for a single-formation front end (one seed, an
            ``(n, 6)`` state); B for the vector env (``seed + b`` or a list of
            B seeds, an ``(n, 6)`` or ``(B, n, 6)`` state).
    """
    options = check_reset_options(options)
    if num_formations is None:
        seeds = [check_seed(seed)]
        channel = [check_seed(options["channel_seed"], "channel_seed")] if "channel_seed" in options else seeds
    else:
        seeds = formation_seeds(seed, num_formations, "seed")
        channel = (
            formation_seeds(options["channel_seed"], num_formations, "channel_seed")
            if "channel_seed" in options
            else seeds
        )
    initial = options.get("initial_state")
    if initial is not None:
        initial = check_initial_state(config, initial, num_formations)
    return ResetRequest(seeds, channel, initial)


class InitialStates:
    """One initial-state generator per formation, for the batched front ends (vector env, TorchRL env).

    Formation ``b`` reset with seed ``s`` gets ``np.random.default_rng(s)``
    (through ``gymnasium.utils.seeding``), the generator a single
    ``parallel_env`` reset with ``s`` uses, so its draws replay that env's;
    unseeded resets and restarts carry on with the formation's generator, as a
    single env's later ``reset()`` calls do.
    """

    def __init__(self, config: ScenarioConfig, num_formations: int) -> None:
        self.config = config
        # in an object array: restarts pick them by index array
        self._rngs = _generators([seeding.np_random(None)[0] for _ in range(num_formations)])
        self._drawn_from = config  # the config draws use (set_spread)

    def set_spread(self, scale: float) -> None:
        """Draw later initial states from ``spread_config`` at ``scale``.

        0: every formation starts in formation on its lanes; 1: the
        scenario's initial state and noise. A curriculum over the initial
        state sets it between resets; the formations' generators and their
        seeding are unchanged.

        Raises:
            ConfigError: ``scale`` is not a number in [0, 1].
        """
        self._drawn_from = spread_config(self.config, scale)

    def seed(self, seeds: Sequence[int | None], ids: np.ndarray | None = None) -> None:
        """Reseed formations ``ids`` (all if None) with ``seeds`` (None keeps that formation's generator)."""
        index = np.arange(len(self._rngs)) if ids is None else np.asarray(ids)
        for b, s in zip(index, seeds, strict=True):
            if s is not None:
                self._rngs[b] = seeding.np_random(s)[0]

    def draw(self, ids: np.ndarray | None = None) -> np.ndarray:
        """``(len(ids), N, 6)`` initial states of formations ``ids`` (all if None), one draw each."""
        rngs = self._rngs if ids is None else self._rngs[np.asarray(ids)]
        return sample_initial_states(self._drawn_from, list(rngs))


def _generators(generators: list[np.random.Generator]) -> np.ndarray:
    """The generators as a 1-d object array (``np.array`` of a list of them would try to unpack each)."""
    out = np.empty(len(generators), dtype=object)
    out[:] = generators
    return out


# ---------------------------------------------------------------------------- infos


def vessel_mean(values: np.ndarray) -> np.ndarray:
    """The mean over the vessels (axis 1) of ``(B, N, …)`` values, summed vessel by vessel.

    Every front end averages the vessels with this one function (the team
    reward, the per-formation reward components), so they agree bit for bit
    whatever the batch size. It is also several times faster than
    ``values.mean(axis=1)`` on ``(B, N)`` arrays with few vessels, where
    numpy's reduction pays per row.
    """
    total = np.array(values[:, 0], dtype=np.float64)
    for j in range(1, values.shape[1]):
        total += values[:, j]
    total /= values.shape[1]
    return total


def vessel_infos(out: StepOutput, time: np.ndarray) -> dict[str, Any]:
    """The per-vessel info schema (module docstring) as ``(B, N)`` arrays."""
    n = out.reward.shape[1]
    flags = {"collision": out.collision, "out_of_bounds": out.out_of_bounds}
    infos: dict[str, Any] = {
        **{f"reward_{key}": np.array(value, dtype=np.float64) for key, value in out.components.items()},
        "time": np.repeat(np.asarray(time, dtype=np.float64)[:, None], n, axis=1),
        **{key: np.repeat(np.asarray(value, dtype=bool)[:, None], n, axis=1) for key, value in flags.items()},
    }
    if out.commanded_speed is not None:
        infos["commanded_speed"] = np.array(out.commanded_speed, dtype=np.float64)
    infos.update({key: np.array(value, dtype=np.int64) for key, value in out.messages.items()})
    return infos


def formation_infos(out: StepOutput, time: np.ndarray) -> dict[str, Any]:
    """The per-formation info schema (module docstring) as arrays with a leading ``(B,)`` axis."""
    infos: dict[str, Any] = {
        "vessel_rewards": np.array(out.reward, dtype=np.float64),
        **{f"reward_{key}": vessel_mean(value) for key, value in out.components.items()},
        "time": np.array(time, dtype=np.float64),
        "collision": np.array(out.collision, dtype=bool),
        "out_of_bounds": np.array(out.out_of_bounds, dtype=bool),
    }
    if out.commanded_speed is not None:
        infos["commanded_speed"] = np.array(out.commanded_speed, dtype=np.float64)
    totals = np.array(out.message_totals)  # the core's sums over the vessels, copied out of its arrays
    infos.update({key: totals[:, k] for k, key in enumerate(MESSAGE_KEYS)})
    return infos


def action_size_hint(config: ScenarioConfig, size: int) -> str:
    """What to add to a wrong-size action's message: with ``transmit`` an action of the level's size alone is
    one from a policy that does not send the ``transmit`` entry."""
    if config.transmit and size == config.control_dim:
        return (
            f" (the scenario has transmit=True: each vessel's action ends with a transmit entry, > 0 to broadcast; "
            f"a policy that does not send it, with actions of the {config.action_level!r} level's size "
            f"{config.control_dim}, cannot act here)"
        )
    return ""


def reward_terms(infos: Mapping[str, Any]) -> dict[str, Any]:
    """The reward terms of an info (any schema above) by their names: ``{"cross_track": …, …}``."""
    return {name: infos[key] for name, key in zip(REWARD_COMPONENTS, REWARD_INFO_KEYS, strict=True)}


def one_entry(infos: dict[str, Any], index: tuple[int, ...]) -> dict[str, Any]:
    """The info of one entry of a stacked info tree, with scalars as Python ``float``/``bool``."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if isinstance(value, dict):
            out[key] = one_entry(value, index)
        else:
            item = value[index]
            out[key] = item.item() if np.ndim(item) == 0 else item.copy()
    return out


# ---------------------------------------------------------------------------- rendering


class Rendering:
    """The renderer of a front end: created on the first frame (matplotlib is imported then), closed once.

    Args:
        config: the scenario (the camera frames its workspace).
        render_mode: ``"rgb_array"``, ``"human"`` or None (then ``frame``
            warns and returns None, as gymnasium's envs do).
        width: frame width in pixels (the height follows the workspace's shape).
    """

    def __init__(self, config: ScenarioConfig, render_mode: str | None, width: int = 1280) -> None:
        self.config = config
        self.render_mode = render_mode
        self.width = width
        self._renderer: Any = None

    def frame(self, core: FormationCore, b: int = 0) -> np.ndarray | None:
        """Draw formation ``b`` of ``core``: an ``(H, W, 3)`` uint8 image (``rgb_array``), or None."""
        if self.render_mode is None:
            warnings.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'", stacklevel=3
            )
            return None
        if self._renderer is None:
            from marine_formation_env.render import FormationRenderer

            self._renderer = FormationRenderer(self.config, human=self.render_mode == "human", width_px=self.width)
        image: np.ndarray | None = self._renderer.draw(
            core.state[b], float(core.time[b]), core.links_up(b), core.arc[b]
        )
        return image

    def close(self) -> None:
        """Close the figure, if one was opened."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
