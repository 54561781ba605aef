"""What a policy's action means: the affine maps between the normalized box and physical commands.

Actions are ``Box(-1, 1)`` at every level (docs/model.md §6):

* ``force``: ``τ_u = a₀·tau_u_max`` [m/s²], ``τ_r = a₁·tau_r_max`` [rad/s²];
* ``guidance``: ``u_c = U_min + (a₀+1)/2·(U_max−U_min)`` [m/s], ``ψ_d = a₁·psi_max`` [rad];
* ``speed``: ``u_c`` as above.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from marine_formation_env.scenarios import ScenarioConfig

__all__ = ["LEVEL_COMMANDS", "action_space", "map_actions", "normalized_actions", "physical_commands"]

#: The physical command behind each action entry of a level, in the action's order
#: (the keys of ``physical_commands``).
LEVEL_COMMANDS = {"force": ("tau_u", "tau_r"), "guidance": ("u_c", "psi_d"), "speed": ("u_c",)}


def action_space(config: ScenarioConfig, joint: bool = False) -> spaces.Box:
    """One vessel's action space ``Box(-1, 1, (A,))`` (``joint``: the N vessels' ``(N·A,)``)."""
    size = config.n_vessels * config.action_dim if joint else config.action_dim
    return spaces.Box(-1.0, 1.0, (size,), dtype=np.float32)


def physical_commands(config: ScenarioConfig, actions: np.ndarray) -> dict[str, np.ndarray]:
    """Map normalized actions ``(..., A)`` (clipped to [−1, 1]) to the level's physical commands.

    * ``force``: ``τ_u = a₀·tau_u_max`` [m/s²], ``τ_r = a₁·tau_r_max`` [rad/s²].
    * ``guidance``: ``u_c = U_min + (a₀+1)/2·(U_max−U_min)`` [m/s], ``ψ_d = a₁·psi_max`` [rad].
    * ``speed``: ``u_c`` as above.
    """
    return map_actions(config, np.clip(actions, -1.0, 1.0))


def map_actions(cfg: ScenarioConfig, a: np.ndarray) -> dict[str, np.ndarray]:
    """``physical_commands`` of actions already inside [−1, 1]."""
    if cfg.action_level == "force":
        return {"tau_u": a[..., 0] * cfg.tau_u_max, "tau_r": a[..., 1] * cfg.tau_r_max}
    u_c = cfg.u_min + 0.5 * (a[..., 0] + 1.0) * (cfg.u_max - cfg.u_min)
    if cfg.action_level == "guidance":
        return {"u_c": u_c, "psi_d": a[..., 1] * cfg.psi_max}
    return {"u_c": u_c}


def normalized_actions(config: ScenarioConfig, **commands: np.ndarray) -> np.ndarray:
    """Inverse of ``physical_commands`` (clipped to [−1, 1]), shape ``(..., A)``."""
    cfg = config
    if cfg.action_level == "force":
        cols = [commands["tau_u"] / cfg.tau_u_max, commands["tau_r"] / cfg.tau_r_max]
    else:
        cols = [2.0 * (np.asarray(commands["u_c"]) - cfg.u_min) / (cfg.u_max - cfg.u_min) - 1.0]
        if cfg.action_level == "guidance":
            cols.append(np.asarray(commands["psi_d"]) / cfg.psi_max)
    return np.clip(np.stack(np.broadcast_arrays(*cols), axis=-1), -1.0, 1.0)
