"""PettingZoo ParallelEnv: a one-formation view of ``FormationCore``."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from marine_formation_env.actions import action_space
from marine_formation_env.core import StepOutput, reset_output
from marine_formation_env.frontend import (
    Rendering,
    action_size_hint,
    one_entry,
    open_front_end,
    read_reset,
    vessel_infos,
)
from marine_formation_env.observations import observation_space
from marine_formation_env.scenarios import ScenarioConfig, sample_initial_state

__all__ = ["MarineFormationParallelEnv", "parallel_env"]


class MarineFormationParallelEnv(ParallelEnv[str, np.ndarray, np.ndarray]):
    """Coordinated path following of underactuated surface vessels under a directed graph.

    ## Description

    ``n`` underactuated 3-DOF surface vessels (surge and yaw actuated, sway
    not; the supply vessel of Fossen et al. 1996 by default) must follow
    parallel straight paths ``y = D_yj`` and line up along them in a formation
    ``x_j − D_xj = x_k − D_xk`` while moving at ``u_d(t)``, as in "Formation
    Control of Underactuated Marine Vehicles with Communication Constraints".
    A directed communication graph decides what each vessel knows of the
    others: vessel ``j`` receives ``(x_i, ẋ_i)`` only from ``i ∈ A_j``. Agents
    are ``vessel_0 … vessel_{n−1}``; all share one observation and one action
    space (parameter sharing). The default scenario ``paper`` is the paper's
    Section V (docs/model.md §5). The path can also be curved (a circle, a
    waypoint route, a lawnmower survey: "Paths" below); the paper's straight
    lines are the default and its special case.

    ## Action Space

    ``Box(-1, 1, (A,), float32)`` per agent, at the chosen ``action_level``.
    Finite values outside [−1, 1] are clipped; NaN/inf raise. The policy acts
    once per control period ``dt``; the built-in loops run inside the
    integrator (every RK4 stage of every substep). `force` inputs and the
    `guidance` heading are held over the period. The commanded speed u_c
    (`speed`, `guidance`) is ramped linearly from the previous command to the
    new one over the period (first-order hold; the first command after a reset
    is held) and the surge law (11) gets the ramp's slope as u̇_c, which (11)
    needs: a held u_c would make u lag it by 1/(k_u + d11/m11) ≈ 2 s, and that
    lag destabilizes the consensus on one-way rings of four or more vessels.
    The ramp stays inside [U_min, U_max]; a command that jumps by Δ asks for a
    surge acceleration of about Δ/dt. At every level the vessel has the same
    actuators: the built-in loops' τ_u, τ_r saturate at ±tau_u_max, ±tau_r_max.

    | level      | index | meaning                      | unit   | a = −1        | a = +1       |
    |------------|-------|------------------------------|--------|---------------|--------------|
    | `force`    | 0     | surge acceleration τ_u       | m/s²   | −tau_u_max    | +tau_u_max   |
    | `force`    | 1     | yaw acceleration τ_r         | rad/s² | −tau_r_max    | +tau_r_max   |
    | `guidance` | 0     | commanded speed u_c          | m/s    | U_min         | U_max        |
    | `guidance` | 1     | commanded heading ψ_d        | rad    | −psi_max      | +psi_max     |
    | `speed`    | 0     | commanded speed u_c          | m/s    | U_min         | U_max        |

    Maps are affine: ``u_c = U_min + (a+1)/2·(U_max − U_min)``, ``τ = a·τ_max``,
    ``ψ_d = a·psi_max``. At `guidance` the surge law (11) and a heading loop
    (14 with ψ_d in place of ψ_LOS, and 13) track ``(u_c, ψ_d)`` (on a curved
    path ψ_d is relative to the path's tangent at the vessel); at `speed` the
    paper's LOS path follower (11)-(14) steers and tracks ``u_c``, so the policy
    does the coordination (20). Defaults: tau_u_max = 3 m/s², tau_r_max =
    2 rad/s² (the paper's gains need up to 2.43 m/s² and 1.82 rad/s² in the
    `paper` scenario), psi_max = π/2.

    With ``transmit=True`` each vessel also decides when it broadcasts: its
    action gets one more, last entry, ``transmit`` (> 0: broadcast at this
    control period, combined with the channel's schedule and budget; see
    "Communication channel"), so ``A`` grows by one. A policy that sends only
    the level's entries is refused with a message that says so.

    ## Observation Space

    ``Box(low, high, (10 + 4·(n−1),), float32)`` per agent; own quantities
    first, then one 4-entry slot per other vessel ``i = (j + k + 1) mod n``,
    ``k = 0 … n−2``. Slot entries are zero when ``i ∉ A_j``. The bounds are
    finite (``FormationCore.observation_space`` documents each): the workspace
    and the speed envelope bound every entry, and the last observation of a
    formation that leaves them is clipped.

    | index     | observation                              | unit   | min      | max     |
    |-----------|------------------------------------------|--------|----------|---------|
    | 0         | cross-track error e_j = y_j − D_yj       | m      | −Y       | Y       |
    | 1         | heading ψ_j, wrapped                     | rad    | −π       | π       |
    | 2         | surge speed u_j                          | m/s    | −14      | 14      |
    | 3         | sway speed v_j                           | m/s    | −14      | 14      |
    | 4         | yaw rate r_j                             | rad/s  | −1       | 1       |
    | 5         | desired formation speed u_d(t)           | m/s    | U_min    | U_max   |
    | 6         | its rate u̇_d(t)                          | m/s²   | −ρ       | ρ       |
    | 7         | path curvature κ(ℓ_j) at the vessel      | 1/m    | −K       | K       |
    | 8         | path curvature κ(ℓ_j + 100 m), ahead     | 1/m    | −K       | K       |
    | 9         | the vessel's lane offset D_yj            | m      | −D       | D       |
    | 10 + 4k   | link bit: 1 iff i transmits to j (now)   | –      | 0        | 1       |
    | 11 + 4k   | (x_j − D_xj) − (x_i − D_xi)              | m      | −X       | X       |
    | 12 + 4k   | ẋ_j − ẋ_i                                | m/s    | −39.6    | 39.6    |
    | 13 + 4k   | age of the received data (0: ideal link) | s      | 0        | horizon |

    On a curved path the same entries are in path coordinates ("Paths"):
    index 0 is ``e_j``, 1 the heading relative to the path ``β_j = ψ_j − γ(ℓ_j)``,
    and the slots hold ``θ_j − θ_i`` with ``θ = ℓ − D_x`` and ``ℓ̇_j − ℓ̇_i``. On
    the straight path 7 and 8 are 0.

    Over a non-ideal channel (next section) ``x_i`` and ``ẋ_i`` are those of
    the last message received from ``i``, sent ``age`` seconds ago, and the
    link bit is 1 iff the link exists now and has delivered a message since
    reset; j's own quantities are always current.

    Y = workspace y-extent + max |D_y|; X = workspace x-length + spread of D_x;
    ρ = max(2π·amplitude/period of u_d, 0.1); 14 m/s and 1 rad/s are the
    defaults of ``max_speed`` and ``max_yaw_rate`` (39.6 = 2√2·14);
    K = max(0.01, 1/smallest radius of the path); D = max(1 m, max |D_y|). On a
    curved path Y is the ``corridor``.

    Teams of several sizes, one observation length: ``observation_slots=M``
    (M ≥ n − 1) appends M − (n − 1) empty slots, every entry 0 (so the link
    bit says "nothing heard", as for a vessel outside ``A_j``), and the space
    is ``(10 + 4·M,)``. A policy over slots (attention, a graph network) then
    trains on several team sizes in one batch and runs on a larger team
    without padding; the default, M = n − 1, is the layout above.

    With ``transmit=True`` the observation ends with three more entries: the
    share of the vessel's token bucket left (in [0, 1]; 1 without a budget),
    the time since its last broadcast, or since reset before the first [s, 0
    to horizon], and how far what its neighbours predict of it from that
    broadcast is off, ``max(|θ_j − θ̂_j| [m], |ẋ_j − ẋ̂_j| [m/s]·1 s)`` with
    ``θ̂_j = θ_s + ẋ_s·age`` (the event-triggered rule's quantity, 0 right
    after a broadcast, at most 10 m and 10 m before the first); the space is
    ``(10 + 4·M + 3,)``.

    Nothing else of another vessel reaches ``j``: what ``i`` transmits is
    ``(x_i, ẋ_i)`` (docs/model.md §3), given relative to ``j``. ``state()`` returns the
    global state ``(n·6 + 1,)``: every vessel's ``x, y, ψ (wrapped), u, v, r``
    followed by the time [s], for centralized critics.

    ## Communication channel, switching graphs, currents, sensor noise

    The paper's links are ideal; the paper is motivated by acoustic modems
    (errors, delay, little bandwidth) and shared radio channels. ``channel=``
    (``ChannelConfig`` or a mapping)
    puts a channel between what vessels transmit and what the others observe:
    Bernoulli or Gilbert–Elliott loss per link, fixed plus random latency
    (messages are time-stamped; none is seen before it could have arrived),
    a transmission period or TDMA round robin on one shared channel, a range
    limit and random link failures with recovery. ``topology_schedule=`` switches
    among graphs periodically. ``current=`` adds an ocean current to the
    kinematics (``u, v`` are then velocities through the water);
    ``sensor_noise=`` adds noise to each vessel's measurement of itself. The
    scenarios ``acoustic``, ``radio`` and ``current`` preset them (docs/channel.md,
    "Presets"). The channel draws from its own stream, seeded with
    the reset seed (or ``options={"channel_seed": k}``). With the defaults
    nothing of this runs.

    Communication is a resource the env counts, budgets and lets agents decide
    on (docs/channel.md, "Communication as a resource"). Every message is
    counted per vessel and control instant: ``infos[agent]`` holds
    ``messages_attempted``, ``messages_sent``, ``messages_delivered``,
    ``messages_dropped_loss``, ``messages_dropped_range``,
    ``messages_dropped_schedule``, ``messages_dropped_budget`` and
    ``bits_sent`` (``channel.message_bits`` per message, 96 by default), the
    reset instant's in ``reset()``'s infos. ``channel={"event_threshold": δ}``
    broadcasts on events: a vessel sends when its neighbours' prediction of it
    from its last broadcast is off by δ (``min_interval`` τ_min apart at least,
    a ``heartbeat`` T_max at most); δ = 0 is periodic broadcasting exactly.
    ``channel={"budget_rate": …, "budget_burst": …}`` gives each vessel a token
    bucket [bit/s, bit]; the presets ``paper_budget`` and ``acoustic_budget``
    set budgets that periodic broadcasting exceeds several times over.

    ## Paths

    ``path=`` (``marine_formation_env.paths``; docs/paths.md) sets the
    reference path ``P(ℓ)``, ``ℓ`` its arc length, with tangent angle ``γ(ℓ)``
    and curvature ``κ(ℓ)``: a path object, a kind name, or a mapping with
    ``kind`` (``{"kind": "circle", "radius": 400.0}``; a mapping without
    ``kind`` updates the scenario's path; ``--set path.radius=500`` on the
    command line). Kinds: ``straight`` (default, ``P(ℓ) = (ℓ, 0)``), ``circle``
    (radius, turn), ``waypoints`` (legs joined by arcs of ``turn_radius``),
    ``lawnmower`` (legs, leg_length, spacing, turn_radius, first_turn).
    Vessel ``j`` follows the lane ``P(ℓ) + D_yj·n(ℓ)``, ``n = (−sin γ, cos γ)``.
    Its path coordinates: the projection ``ℓ_j`` (followed continuously: a
    global search at reset, Newton steps after every RK4 step), ``e_j = (p_j −
    P(ℓ_j))·n − D_yj``, ``β_j = ψ_j − γ(ℓ_j)``, ``θ_j = ℓ_j − D_xj`` and
    ``ℓ̇_j = (u cos β − v sin β)/(1 − κ·(D_yj + e_j))``; on the straight path
    they are ``x_j``, ``y_j − D_yj``, ``ψ_j``, ``x_j − D_xj``, ``ẋ_j``. What
    vessels transmit is ``(ℓ_i, ℓ̇_i)``. The built-in LOS (`speed`) steers to
    ``γ(ℓ) − atan(e/Δ)`` less the crab angle of steady turning; the reference
    commands the lane's surge speed (the outer vessel of a turn goes faster).
    A path and formation that break the generalized assumption (19), every
    ``(1 − κ·D_yj)·(u_d ± a)`` inside [U_min, U_max], are refused (naming the
    lane, the radius and the band); so are waypoints that a ``turn_radius``
    cannot join. Presets: ``circle`` (the paper's formation on a circle of
    300 m, the smallest radius (19) admits), ``survey`` (a lawnmower of 4 legs
    of 2 km, 600 m apart, turns of 300 m; horizon 2000 s) and
    ``survey_acoustic`` (that route over ``acoustic`` links). Both backends
    run curved paths (the compiled kernel follows the projections too).

    ## Rewards

    Per vessel and step, with ``c(e; σ) = (e/σ)²/(1 + (e/σ)²) ∈ [0, 1)`` and
    ``θ_j = x_j − D_xj``::

        r_j = −dt·[ 1.0·c(e_j; 20 m) + 0.25·c(ψ_j; 0.2 rad)
                    + 1.0·c(θ_j − mean_k θ_k; 20 m) + 0.5·c(ẋ_j − u_d; 1 m/s)
                    + 0.0·mean(a²) ]

    ``ẋ_j = u_j cos ψ_j − v_j sin ψ_j`` is the along-path speed through the
    water (with a current the vessel is carried on top of it; the rewards, like
    the paper's goals, ask for u_d relative to the water). On a curved path the
    terms take ``e_j``, ``β_j``, ``θ_j = ℓ_j − D_xj`` and ``ℓ̇_j`` in place of
    ``y_j − D_yj``, ``ψ_j``, ``x_j − D_xj`` and ``ẋ_j`` (a vessel crabbing
    through a turn pays a small heading cost). Weights and scales
    are ``reward=RewardConfig(...)`` fields; ``fine_share=f`` (0 here) charges
    the share f of each tracking term named in ``fine_terms`` (all four by
    default) at ``fine_scale`` (0.05) of its σ instead,
    ``(1 − f)·c(e; σ) + f·c(e; 0.05·σ)``, for a learner that
    needs a slope inside the success band (a training option: the benchmark's
    reward is the one above). If the
    formation terminates early, every vessel also receives
    ``−(Σ weights)·(horizon − t)``, the worst the remaining episode could give,
    so ending an episode never pays. ``infos[agent]`` holds every term as
    ``reward_cross_track``, ``reward_heading``, ``reward_coordination``,
    ``reward_speed``, ``reward_effort``, ``reward_terminal`` and
    ``reward_communication`` (``−message_cost`` per broadcast the vessel sends;
    ``message_cost`` is 0 by default); they sum to the reward. A return near 0
    is perfect.

    ## Starting State

    The scenario's nominal state plus uniform noise of half-widths
    ``init_noise`` (x, y [m], ψ [rad], u [m/s]); ``paper``: exactly docs/model.md §5,
    ``(x, y, ψ, u, v, r)`` = (−50, 20, 0, 3, 0, 0), (−60, 30, 0.3, 3, 0, 0),
    (−120, −10, −0.2, 3, 0, 0). ``reset(options={"initial_state": (n, 6)})``
    sets it exactly (inertial columns). A scenario's ``initial_state`` is
    written in the path's frame (arc length, offset along the normal, heading
    relative to the tangent, u, v, r), the inertial frame on the straight path;
    the curved presets carry the paper's initial state onto their path. A
    start that would end the episode before the first
    decision (a vessel outside the workspace or the speed/yaw-rate envelope,
    or two vessels closer than ``safety_distance``) is refused, at
    construction for the scenario's own initial state (with its noise) and at
    ``reset`` for one passed in, with the vessel and the bound named.

    Seeds are whole numbers ≥ 0 (Python or numpy integers); floats, strings
    and negative numbers raise. Unknown ``reset`` options are ignored with a
    warning, the same in every front end.

    ## Episode End

    * Termination (all agents at once): two vessels closer than
      ``safety_distance`` (default 5 m; 0, i.e. off, in `paper`, whose initial
      state makes vessel_0 and vessel_1 cross paths 0.5 m apart under the
      paper's controller, which does not consider collisions), a vessel
      outside ``workspace`` (default: a box holding the whole nominal run with
      500 m / 250 m margins; on a curved path: around the route), on a
      curved path a vessel more than ``corridor`` from its lane (|e_j| >
      corridor; default half the room between the outermost lane and the
      tightest centre of curvature, at most 250 m), a vessel outside the envelope |u|, |v| ≤
      max_speed (14 m/s), |r| ≤ max_yaw_rate (1 rad/s), or a non-finite state
      (``infos[agent]["out_of_bounds"]``).
    * Truncation: after ``round(horizon/dt)`` steps (400 s: 800 steps at the
      default dt of `speed`/`guidance`, 4000 at `force`).

    ## Arguments

    ``marine_formation_env.parallel_env(scenario="paper", render_mode=None, render_speedup=1.0, **overrides)``

    | argument           | default              | meaning                                                    |
    |--------------------|----------------------|------------------------------------------------------------|
    | `scenario`         | `"paper"`            | named defaults (`SCENARIOS`), or a ready `ScenarioConfig`  |
    | `render_mode`      | None                 | `"rgb_array"` or `"human"`                                 |
    | `render_speedup`   | 1                    | `metadata["render_fps"]` = speedup / dt: real time at 1    |
    | `backend`          | `"auto"`             | `numpy` or `numba` (auto: numba if installed); same results |
    | `action_level`     | `"speed"`            | `force`, `guidance` or `speed`                             |
    | `dt`               | 0.1 / 0.5 / 0.5 s    | control period (force / guidance / speed)                  |
    | `substeps`         | ceil(dt / 0.1 s)     | RK4 steps per control period                               |
    | `horizon`          | 400 s                | episode length                                             |
    | `n_vessels`        | 3                    | changing it switches to a generated `v` formation          |
    | `topology`         | `"paper"`            | preset name, `CommGraph` or (n, n) adjacency               |
    | `formation`        | `"paper"`            | pattern name or (n, 2) offsets (D_x, D_y) [m]              |
    | `u_d`              | 5 m/s                | number or `SpeedProfile` (must satisfy (19))               |
    | `u_min`, `u_max`   | 3, 7 m/s             | controllability band                                       |
    | `gains`            | paper's              | `Gains(k_u, k_psi, k_r, delta, a)`                         |
    | `paper_as_printed` | False                | run (11) and (14) as printed (docs/model.md §3)                     |
    | `safety_distance`  | 5 m (`paper`: 0)     | collision distance (0 disables the check)                  |
    | `channel`          | ideal links          | `ChannelConfig` or mapping (previous section)            |
    | `topology_schedule`| none                 | ((dwell s, graph), …) repeated; replaces `topology`       |
    | `current`          | still water          | `Current(speed, direction, amplitude, period)` or mapping  |
    | `sensor_noise`     | none                 | `SensorNoise(position, heading, speed, yaw_rate)` std devs |
    | `los_integral_gain`| 0 (plain LOS)        | σ [m/s]: integral LOS in the `speed` level's path follower |
    | `path`             | `"straight"`         | `Path`, kind name or mapping with `kind` ("Paths")         |
    | `corridor`         | derived (curved)     | largest abs(e_j) [m] on a curved path before termination |
    | `observation_slots`| n − 1                | slots per observation; more pad with empty ones           |
    | `transmit`         | False                | each vessel's policy decides when it broadcasts          |

    A mapping given for a nested setting updates the scenario's value field
    by field: ``parallel_env("acoustic", channel={"latency": 3.0})`` keeps the
    rest of the acoustic channel.

    All fields of ``Settings``
    are accepted; an unknown key raises.

    ## Version History

    * v0: initial release; channel, switching graphs, currents and sensor
      noise added as options whose defaults leave the behaviour unchanged.
      Since 0.3.0, input that used to be accepted silently is refused
      (initial states that end the episode at once, float seeds, schedule
      dwells that are not whole control periods); valid input behaves as before.
    * v1 (0.3.0): curved paths (``path=``). The own part of the observation has
      10 entries (was 7): the path's curvature at the vessel and 100 m ahead
      and the lane offset D_yj follow u̇_d, so the slots start at index 10. Every
      other value, and every state and reward on the straight path, is as in v0.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - the class default; each env sets its own render_fps
        "name": "marine_formation_v1",
        "render_modes": ["human", "rgb_array"],
        "render_fps": 10,
    }

    def __init__(
        self,
        scenario: str | ScenarioConfig = "paper",
        render_mode: str | None = None,
        backend: str = "auto",
        render_speedup: float = 1.0,
        **overrides: Any,
    ) -> None:
        front = open_front_end(type(self).metadata, scenario, overrides, render_mode, render_speedup, backend)
        self.config, self.metadata, self.core = front
        self.render_mode = render_mode
        n = self.config.n_vessels
        self.possible_agents = [f"vessel_{j}" for j in range(n)]
        self.agents: list[str] = []
        self._index = {agent: j for j, agent in enumerate(self.possible_agents)}
        self._observation_space = observation_space(self.config)
        self._action_space = action_space(self.config)
        self.state_space = spaces.Box(-np.inf, np.inf, (n * 6 + 1,), dtype=np.float32)
        self.np_random, self.np_random_seed = seeding.np_random(None)
        self._rendering = Rendering(self.config, render_mode)
        self._started = False

    # ------------------------------------------------------------------ spaces
    def observation_space(self, agent: str) -> spaces.Box:
        """The shared observation space (the same object for every agent)."""
        self._check_agent(agent)
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Box:
        """The shared action space (the same object for every agent)."""
        self._check_agent(agent)
        return self._action_space

    def _check_agent(self, agent: str) -> None:
        if agent not in self._index:
            raise KeyError(f"unknown agent {agent!r}; agents are {self.possible_agents}")

    # ------------------------------------------------------------------- API
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode.

        Args:
            seed: seeds the env's generator (initial-state noise) and, as a
                separate stream, the channel's (loss, delays, link failures,
                sensor noise).
            options: ``{"initial_state": (n, 6) array}`` sets the state exactly
                (columns x, y, psi, u, v, r); ``{"channel_seed": int}`` seeds
                the channel stream on its own (to vary the channel's luck with
                the same initial state). Any other key is ignored with a
                warning (``marine_formation_env.frontend``).

        Raises:
            TypeError: a seed that is not a whole number (numpy integers are
                fine), options that are not a dict, a non-numeric initial state.
            ValueError: a negative seed, an initial state of
                the wrong shape, not finite, or one that would end the episode
                at its first step (outside the workspace or the envelope, or
                two vessels closer than ``safety_distance``).
        """
        request = read_reset(self.config, seed, options)  # every check before anything changes
        if request.seeds[0] is not None:
            self.np_random, self.np_random_seed = seeding.np_random(request.seeds[0])
        initial = request.initial_state
        if initial is None:
            initial = sample_initial_state(self.config, self.np_random)
        self.core.seed_channel(request.channel_seeds)
        obs = self.core.reset(initial)[0]
        self.agents = list(self.possible_agents)
        self._started = True
        if self.render_mode == "human":
            self.render()
        return self._per_agent(obs), self._infos(
            reset_output(obs[None], self.config.action_level != "force", self.core.messages())
        )

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[
        dict[str, np.ndarray],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        """Apply one action per live agent and advance one control period ``dt``.

        Raises:
            RuntimeError: before ``reset`` or after the episode ended.
            KeyError: a live agent's action is missing, or an unknown key is given.
            ValueError: an action of the wrong shape or with NaN/inf.
        """
        if not self._started:
            raise RuntimeError("step() called before reset()")
        if not self.agents:
            raise RuntimeError("the episode has ended (terminated or truncated); call reset() before step()")
        batch = self._action_batch(actions)
        out = self.core.step(batch)
        obs = self._per_agent(out.observation[0])
        rewards = {agent: float(out.reward[0, self._index[agent]]) for agent in self.agents}
        term, trunc = bool(out.terminated[0]), bool(out.truncated[0])
        terminations = dict.fromkeys(self.agents, term)
        truncations = dict.fromkeys(self.agents, trunc)
        infos = self._infos(out)
        if term or trunc:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terminations, truncations, infos

    def state(self) -> np.ndarray:
        """Global state ``(n·6 + 1,)`` float32: all vessels' ``x, y, ψ, u, v, r`` and the time [s]."""
        return self.core.global_state()[0]

    # ------------------------------------------------------------- rendering
    def render(self, mode: str | None = None) -> np.ndarray | None:
        """Draw the formation: ``rgb_array`` returns an ``(H, W, 3)`` uint8 image (even H and W).

        ``mode`` is accepted and ignored (RLlib passes one): the
        ``render_mode`` given at construction decides.
        """
        return self._rendering.frame(self.core)

    @property
    def max_steps(self) -> int:
        """Control periods per episode (``horizon / dt``): the step at which it is truncated."""
        return self.config.max_steps

    def close(self) -> None:
        self._rendering.close()

    # --------------------------------------------------------------- helpers
    @property
    def time(self) -> float:
        """Simulated time since reset [s]."""
        return float(self.core.time[0])

    @property
    def vessel_states(self) -> np.ndarray:
        """``(n, 6)`` float64 copy of the physical state (columns x, y, psi, u, v, r)."""
        return self.core.state[0].copy()

    def _per_agent(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        return {agent: obs[self._index[agent]] for agent in self.possible_agents if agent in self.agents}

    def _action_batch(self, actions: dict[str, Any]) -> np.ndarray:
        if not isinstance(actions, dict):
            raise TypeError(f"actions must be a dict {{agent: action}}, got {type(actions).__name__}")
        unknown = sorted(set(actions) - set(self.agents))
        if unknown:
            raise KeyError(f"actions for unknown or finished agent(s) {unknown}; live agents are {self.agents}")
        missing = [agent for agent in self.agents if agent not in actions]
        if missing:
            raise KeyError(f"missing actions for agent(s) {missing}; every live agent must act")
        dim = self.config.action_dim
        batch = np.empty((1, self.config.n_vessels, dim))
        for agent, action in actions.items():
            try:
                arr = np.asarray(action, dtype=float).reshape(-1)
            except (TypeError, ValueError):
                raise ValueError(f"action of {agent} must be numeric, got {action!r}") from None
            if arr.shape != (dim,):
                hint = action_size_hint(self.config, arr.size)
                raise ValueError(f"action of {agent} must have shape ({dim},), got {np.shape(action)}{hint}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"action of {agent} must be finite, got {arr.tolist()}")
            batch[0, self._index[agent]] = arr
        return batch

    def _infos(self, out: StepOutput) -> dict[str, dict[str, Any]]:
        """``{agent: info}`` in the per-vessel schema (``marine_formation_env.frontend``)."""
        stacked = vessel_infos(out, self.core.time)
        return {agent: one_entry(stacked, (0, self._index[agent])) for agent in self.agents}


def parallel_env(
    scenario: str | ScenarioConfig = "paper", render_mode: str | None = None, **overrides: Any
) -> MarineFormationParallelEnv:
    """Create the PettingZoo ParallelEnv (see ``MarineFormationParallelEnv``)."""
    return MarineFormationParallelEnv(scenario=scenario, render_mode=render_mode, **overrides)
