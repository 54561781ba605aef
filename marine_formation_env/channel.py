"""Communication channel between what vessels transmit and what the others observe.

The paper analyses ideal links: vessel ``j`` knows ``(x_i, ẋ_i)`` of every
``i ∈ A_j`` at every instant. It is motivated by links that are not ideal:
acoustic modems "plagued with errors, transmission delay, multi-path fading"
with little bandwidth, and radio channels on which "only one vehicle can
transmit ... at a time", with links lost "due to failures or vessels moving out
of range". This module models those conditions (our extension; the defaults
are the ideal links of the paper).

Timing (everything happens at the control instants ``t_k = k·dt``):

1. **Which links exist now.** Link ``i → j`` exists at ``t_k`` iff it is in the
   communication graph at ``t_k`` (the scenario's ``topology``, or the graph of
   ``topology_schedule`` active at ``t_k``), the vessels are at most ``range``
   apart, and the link has not randomly failed (failure rate λ, recovery rate
   μ per second: per control period a live link fails with probability
   ``1 − e^{−λ·dt}``, a failed one recovers with ``1 − e^{−μ·dt}``; every link
   is live at reset).
2. **When a vessel may transmit** (its opportunities). Without TDMA at
   ``t_k`` when ``k`` is a multiple of ``period/dt`` (``period = None``: every
   control period). With TDMA (``tdma_slot``) the channel carries one
   transmitter per slot, round robin: vessel ``i`` may transmit when
   ``k mod (n·S) = i·S`` with ``S = tdma_slot/dt``, so every
   ``n·tdma_slot`` seconds.
3. **Whether it tries** (its attempts). Periodic broadcasting (the default)
   uses every opportunity. **Event-triggered** broadcasting
   (``event_threshold`` δ) uses an opportunity only when the prediction its
   neighbours make of it from its last broadcast ``(θ_s, ẋ_s, t_s)``,
   ``θ̂ = θ_s + ẋ_s·(t_k − t_s)`` and ``ẋ̂ = ẋ_s``, is off by
   ``max(|θ − θ̂| [m], |ẋ − ẋ̂|·1 s) ≥ δ``, and at least ``min_interval``
   τ_min after its last broadcast (no Zeno behaviour); it also uses one
   ``heartbeat`` T_max after its last broadcast whatever the error, and its
   first opportunity after reset. With δ = 0 and τ_min = dt this is periodic
   broadcasting exactly. With ``ScenarioConfig.transmit`` the vessel's policy
   decides at every control instant (the action's last entry > 0); an
   attempt outside the vessel's opportunities is dropped (by *schedule*).
4. **Budget.** With ``budget_rate`` each vessel has a token bucket of
   ``budget_burst`` bits, full at reset, refilled by ``budget_rate·dt`` bits at
   every later control instant (never above ``budget_burst``); a broadcast
   costs ``message_bits`` bits and is not sent without them (dropped by
   *budget*).
5. **Loss.** A message from ``i`` reaches ``j`` only if the link exists at
   sending and survives an independent loss draw per link and message:
   Bernoulli(``loss``), or the Gilbert–Elliott chain of ``GilbertElliott``
   (one chain per link, advanced once per message sent on it).
6. **Latency.** A message is time-stamped at sending, ``t_s = t_k``; it arrives
   ``latency + jitter·U`` seconds later (``U ~ Uniform[0, 1)``) and is
   delivered at the first control instant at or after its arrival time, never
   before. A latency of ``m·dt`` delays it by exactly ``m`` control periods.
7. **What is observed.** Vessel ``j`` holds, per link, the newest message
   received (zero-order hold; a late message never replaces a newer one). Its
   observation slot for ``i`` shows ``(link, θ_j − θ_i(t_s), ẋ_j − ẋ_i(t_s),
   t_k − t_s)`` where ``link = 1`` iff the link exists now *and* has delivered
   at least one message since reset; otherwise the slot is all zeros.

Every message is counted (``COUNTERS``), per vessel and control instant:
``attempted`` and ``sent`` broadcasts, ``dropped_schedule`` and
``dropped_budget`` attempts, and per link of the communication graph out of a
sent broadcast ``delivered`` (survived the link: on its way or arrived),
``dropped_loss`` and ``dropped_range`` (the link was down: out of range or
failed). Bits on the channel are ``sent × message_bits``.

With the default ``ChannelConfig`` nothing of this runs and the
observations are those of the ideal links; with a configuration that exists
but does not impair (zero loss, zero latency, every period, unlimited range)
the channel path reproduces them bit for bit (tests/test_channel.py).

Randomness comes only from the channel stream of each formation, separate
from its initial-state generator (``marine_formation_env.streams``).
``LinkChannel`` takes only what it uses: its ``ChannelConfig``, the
number of vessels, the control period, the graph schedule and the episode
length.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from marine_formation_env.errors import ConfigError, build_config, check_number, whole_periods
from marine_formation_env.streams import BlockStream, channel_streams

# BlockStream and channel_streams are re-exported from marine_formation_env.streams
__all__ = [
    "COUNTERS",
    "MESSAGE_BITS",
    "BlockStream",
    "ChannelConfig",
    "GilbertElliott",
    "LinkChannel",
    "channel_streams",
    "event_due",
    "in_range",
    "prediction_error",
]


#: ``next_arrival`` of a formation with no message on its way.
NEVER = np.iinfo(np.int64).max
#: The message counters (``LinkChannel.counts``), in their order: per broadcast the first two and the last
#: two, per link of the communication graph out of a sent broadcast the three in between.
COUNTERS = ("attempted", "sent", "delivered", "dropped_loss", "dropped_range", "dropped_schedule", "dropped_budget")
#: ``LinkChannel.mode``: who decides when a vessel broadcasts.
PERIODIC, EVENT, TRANSMIT = 0, 1, 2
ATTEMPTED, SENT, DELIVERED, LOSS, RANGE, SCHEDULE, BUDGET = range(len(COUNTERS))
#: One message's size [bit] by default: θ, ẋ and the send time, 32 bits each.
MESSAGE_BITS = 96
#: Control periods since the last broadcast of a vessel that has not broadcast since reset.
NOT_SENT = 1 << 40


def prediction_error(theta: Any, xdot: Any, sent_theta: Any, sent_xdot: Any, elapsed: Any) -> Any:
    """How far the neighbours' prediction of a vessel from its last broadcast is off.

    The neighbours predict ``θ̂ = θ_s + ẋ_s·elapsed`` and ``ẋ̂ = ẋ_s`` from the
    broadcast ``(θ_s, ẋ_s)`` sent ``elapsed`` seconds ago (as the extrapolating
    reference does); the error is ``max(|θ − θ̂| [m], |ẋ − ẋ̂| [m/s]·1 s)``.
    Scalars or arrays: the compiled channel calls this function too.
    """
    return np.maximum(np.abs(theta - (sent_theta + sent_xdot * elapsed)), np.abs(xdot - sent_xdot))


def event_due(error: Any, threshold: float, since: Any, min_steps: int, heartbeat_steps: int) -> Any:
    """Whether an event-triggered vessel uses an opportunity to broadcast.

    ``since`` control periods after its last broadcast (``NOT_SENT`` before
    the first): when the prediction ``error`` has reached ``threshold`` δ and
    ``min_steps`` periods have passed, or ``heartbeat_steps`` have.
    """
    return (since >= heartbeat_steps) | ((error >= threshold) & (since >= min_steps))


def in_range(dx: Any, dy: Any, link_range: float) -> Any:
    """Whether two vessels ``(dx, dy)`` [m] apart are within ``link_range`` [m] of each other.

    Compares squared distances: no square root, and the same arithmetic on
    both backends (the compiled channel calls this function too).
    """
    return dx * dx + dy * dy <= link_range * link_range


def _probability(owner: str, key: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0.0 <= value <= 1.0):
        raise ConfigError(f"{owner}.{key} must be a probability in [0, 1], got {value!r}")


@dataclass(frozen=True)
class GilbertElliott:
    """Bursty packet loss: a two-state (good/bad) Markov chain per link.

    Before each message on a link the chain moves good → bad with probability
    ``p_good_to_bad`` and bad → good with ``p_bad_to_good``; the message is then
    lost with ``loss_good`` or ``loss_bad``. The chain starts in its stationary
    distribution, so the long-run loss rate is ``mean_loss`` from the first
    message on, and a bad spell lasts ``1/p_bad_to_good`` messages on average.

    Attributes:
        p_good_to_bad, p_bad_to_good: transition probabilities per message.
        loss_good, loss_bad: loss probability in each state.
    """

    p_good_to_bad: float = 0.05
    p_bad_to_good: float = 0.3
    loss_good: float = 0.0
    loss_bad: float = 1.0

    def __post_init__(self) -> None:
        for key in ("p_good_to_bad", "p_bad_to_good", "loss_good", "loss_bad"):
            _probability("channel.burst", key, getattr(self, key))
        if self.p_good_to_bad + self.p_bad_to_good == 0:
            raise ConfigError(
                "channel.burst needs p_good_to_bad + p_bad_to_good > 0 (a chain that never moves has no "
                "stationary distribution)"
            )

    @property
    def p_bad(self) -> float:
        """Stationary probability of the bad state."""
        return self.p_good_to_bad / (self.p_good_to_bad + self.p_bad_to_good)

    @property
    def mean_loss(self) -> float:
        """Long-run fraction of messages lost."""
        return self.p_bad * self.loss_bad + (1.0 - self.p_bad) * self.loss_good


@dataclass(frozen=True)
class ChannelConfig:
    """How messages travel between vessels (module docstring); the defaults are ideal links.

    Attributes:
        loss: Bernoulli loss probability per link and message, in [0, 1]; or
            an ``(n, n)`` matrix of them, ``loss[j][i]`` for the link i → j.
        burst: Gilbert–Elliott bursty loss instead of ``loss`` (a
            ``GilbertElliott`` or a mapping of its fields); None: Bernoulli.
        latency: fixed delay from sending to arrival [s], ≥ 0.
        jitter: random extra delay, uniform in [0, jitter) [s], ≥ 0.
        period: each vessel transmits every ``period`` seconds (a multiple of
            the control period dt); None: every control period.
        tdma_slot: TDMA slot length [s] (a multiple of dt): one transmitter per
            slot, round robin, so each vessel transmits every ``n·tdma_slot``;
            None: no TDMA. Excludes ``period``.
        range: links exist only between vessels at most this far apart [m]
            (``inf``: unlimited).
        failure_rate: rate λ at which a live link fails [1/s] (0: never).
        recovery_rate: rate μ at which a failed link recovers [1/s] (0: never).
        message_bits: one message's size [bit] (default ``MESSAGE_BITS``: θ,
            ẋ and the send time, 32 bits each).
        event_threshold: δ ≥ 0 of event-triggered broadcasting [m, and m/s
            for the velocity]; ``inf`` with a ``heartbeat``: a broadcast every
            ``heartbeat`` seconds (at the first opportunity then); None:
            periodic broadcasting at every opportunity.
        min_interval: τ_min [s] between two broadcasts of a vessel under event
            triggering, a whole number of control periods; None: dt.
        heartbeat: T_max [s]: an event-triggered vessel broadcasts at its first
            opportunity this long after its last broadcast; None: never forced.
        budget_rate: the token bucket's refill rate [bit/s], > 0; None: no budget.
        budget_burst: the bucket's size [bit], at least one message; None: one
            message (``message_bits``).
    """

    loss: float = 0.0
    burst: Any = None
    latency: float = 0.0
    jitter: float = 0.0
    period: Any = None
    tdma_slot: Any = None
    range: float = math.inf
    failure_rate: float = 0.0
    recovery_rate: float = 0.0
    message_bits: int = MESSAGE_BITS
    event_threshold: Any = None
    min_interval: Any = None
    heartbeat: Any = None
    budget_rate: Any = None
    budget_burst: Any = None

    def __post_init__(self) -> None:
        if isinstance(self.loss, (list, tuple, np.ndarray)):
            try:
                matrix = np.asarray(self.loss, dtype=float)
            except (TypeError, ValueError):
                raise ConfigError(
                    f"channel.loss must be a probability or a matrix of them, got {self.loss!r}"
                ) from None
            if matrix.ndim != 2 or matrix.shape[0] != matrix.shape[1]:
                raise ConfigError(f"channel.loss as a matrix must be square (n, n), got shape {matrix.shape}")
            bad = np.argwhere(~((matrix >= 0) & (matrix <= 1)))
            if bad.size:
                j, i = bad[0]
                raise ConfigError(
                    f"channel.loss[{j}][{i}] must be a probability in [0, 1], got {float(matrix[j, i])!r} "
                    f"(link {i} → {j})"
                )
            object.__setattr__(self, "loss", tuple(tuple(float(v) for v in row) for row in matrix))
        else:
            _probability("channel", "loss", self.loss)
        if self.burst is not None and not isinstance(self.burst, GilbertElliott):
            if not isinstance(self.burst, Mapping):
                raise ConfigError(f"channel.burst must be a GilbertElliott, a mapping or None, got {self.burst!r}")
            object.__setattr__(self, "burst", build_config(GilbertElliott, self.burst, "channel.burst"))
        if self.burst is not None and np.any(np.asarray(self.loss) > 0):
            raise ConfigError(
                f"give either channel.loss (Bernoulli, got {self.loss}) or channel.burst (Gilbert–Elliott), not both"
            )
        check_number("channel", "latency", self.latency)
        check_number("channel", "jitter", self.jitter)
        for key in ("period", "tdma_slot"):
            if getattr(self, key) is not None:
                check_number("channel", key, getattr(self, key), strict=True)
        if self.period is not None and self.tdma_slot is not None:
            raise ConfigError(
                f"give either channel.period ({self.period} s) or channel.tdma_slot ({self.tdma_slot} s): with TDMA "
                "each vessel transmits every n·tdma_slot seconds"
            )
        rng = self.range
        if isinstance(rng, bool) or not isinstance(rng, (int, float)) or math.isnan(rng) or not rng > 0:
            raise ConfigError(f"channel.range must be a distance > 0 m (inf: unlimited), got {rng!r}")
        check_number("channel", "failure_rate", self.failure_rate)
        check_number("channel", "recovery_rate", self.recovery_rate)
        self._check_traffic()

    def _check_traffic(self) -> None:
        """The message size, event triggering and the budget."""
        bits = self.message_bits
        if isinstance(bits, bool) or not isinstance(bits, (int, np.integer)) or bits < 1:
            raise ConfigError(f"channel.message_bits must be a whole number of bits ≥ 1, got {bits!r}")
        object.__setattr__(self, "message_bits", int(bits))
        if self.event_threshold is None:
            for key in ("min_interval", "heartbeat"):
                if getattr(self, key) is not None:
                    raise ConfigError(
                        f"channel.{key} = {getattr(self, key)!r} applies to event-triggered broadcasting only: "
                        "give channel.event_threshold too"
                    )
        else:
            delta = self.event_threshold
            if isinstance(delta, bool) or not isinstance(delta, (int, float)) or not delta >= 0:
                raise ConfigError(
                    f"channel.event_threshold must be a number δ ≥ 0 (inf: heartbeat only), got {delta!r}"
                )
            if math.isinf(delta) and self.heartbeat is None:
                raise ConfigError(
                    "channel.event_threshold = inf sends only the first message: give channel.heartbeat (periodic "
                    "broadcasting every heartbeat seconds)"
                )
            for key in ("min_interval", "heartbeat"):
                if getattr(self, key) is not None:
                    check_number("channel", key, getattr(self, key), strict=True)
            if self.heartbeat is not None and self.min_interval is not None and self.heartbeat < self.min_interval:
                raise ConfigError(
                    f"channel.heartbeat = {self.heartbeat} s must be at least channel.min_interval = "
                    f"{self.min_interval} s"
                )
        if self.budget_rate is None:
            if self.budget_burst is not None:
                raise ConfigError(
                    f"channel.budget_burst = {self.budget_burst!r} needs channel.budget_rate (the bucket's refill rate)"
                )
            return
        check_number("channel", "budget_rate", self.budget_rate, strict=True)
        if self.budget_burst is not None:
            check_number("channel", "budget_burst", self.budget_burst, strict=True)
            if self.budget_burst < self.message_bits:
                raise ConfigError(
                    f"channel.budget_burst = {self.budget_burst} bit must hold one message of "
                    f"channel.message_bits = {self.message_bits} bit"
                )

    @property
    def is_ideal(self) -> bool:
        """The paper's ideal links: the default configuration, whatever the message size."""
        return dataclasses.replace(self, message_bits=MESSAGE_BITS) == ChannelConfig()

    @property
    def event_triggered(self) -> bool:
        """Vessels broadcast on events (``event_threshold``), not periodically."""
        return self.event_threshold is not None

    @property
    def has_budget(self) -> bool:
        """A token bucket limits each vessel's broadcasts (``budget_rate``)."""
        return self.budget_rate is not None

    @property
    def bucket(self) -> float:
        """The token bucket's size [bit] (``budget_burst``, default one message)."""
        return float(self.message_bits if self.budget_burst is None else self.budget_burst)

    def event_steps(self, dt: float) -> tuple[int, int]:
        """``(τ_min, T_max)`` in control periods (``NEVER`` without a heartbeat)."""
        min_steps = 1 if self.min_interval is None else whole_periods(self.min_interval, dt, "channel.min_interval")
        beat = NEVER if self.heartbeat is None else whole_periods(self.heartbeat, dt, "channel.heartbeat")
        return min_steps, beat

    @property
    def max_delay(self) -> float:
        """The longest delay a message can have [s]."""
        return self.latency + self.jitter

    def period_steps(self, dt: float) -> int:
        """Control periods between two transmissions of one vessel without TDMA."""
        return 1 if self.period is None else whole_periods(self.period, dt, "channel.period")

    def slot_steps(self, dt: float) -> int:
        """Control periods per TDMA slot (requires ``tdma_slot``)."""
        return whole_periods(self.tdma_slot, dt, "channel.tdma_slot")

    def validate(self, dt: float, n: int) -> None:
        """Checks that need the scenario: ``period`` and ``tdma_slot`` are multiples
        of the control period ``dt``; a loss matrix is ``(n, n)``."""
        self.period_steps(dt)
        if self.tdma_slot is not None:
            self.slot_steps(dt)
        self.event_steps(dt)
        if isinstance(self.loss, tuple) and np.shape(self.loss) != (n, n):
            raise ConfigError(f"channel.loss as a matrix must have shape ({n}, {n}), got {np.shape(self.loss)}")


class LinkChannel:
    """The channel state of ``B`` formations of ``N`` vessels, held by ``FormationCore``.

    Arrays are indexed ``[b, j, i]`` for the link ``i → j`` (receiver ``j``,
    sender ``i``), like ``A[j, i]`` of the graph. The pending ring buffer has
    one slot per possible delay in control periods, up to the episode's length
    (a message that would arrive after the last step of an episode is
    dropped); messages sharing an arrival instant on one link keep only the newest.

    Attributes:
        up: ``(B, N, N)`` the link exists now.
        has_message: ``(B, N, N)`` a message has been received on the link since reset.
        held_theta, held_xdot, held_time: the held message: ``θ_i = x_i − D_xi``
            [m], inertial ``ẋ_i`` [m/s], and its send time [s].
        transmitted: ``(B, N)`` which vessels transmitted at the last update.
        failed, bad: ``(B, N, N)`` the link has failed; its Gilbert–Elliott chain is bad.
        pend_valid, pend_theta, pend_xdot, pend_time: ``(B, depth, N, N)`` the
            messages on their way, by arrival slot ``step mod depth``
            (formation-major: one formation's messages are adjacent in memory).
        next_arrival: ``(B,)`` the first control period at which one of them
            arrives (``NEVER``: none on its way).
        graphs, ends: the schedule's adjacencies ``(G, N, N)`` and the end of
            each dwell within one cycle [s].
        tdma, every: TDMA on; control periods per slot (TDMA) or per transmission.
        p_fail, p_recover: per-period failure and recovery probabilities.
        loss_matrix: the Bernoulli loss (a probability or an ``(N, N)`` matrix).
        mode: ``PERIODIC``, ``EVENT`` (``event_threshold``) or ``TRANSMIT`` (the policies decide).
        sent_theta, sent_xdot, sent_time, sent_step: ``(B, N)`` each vessel's last
            broadcast (``θ_s = inf``, ``sent_step = −NOT_SENT`` before the first).
        tokens: ``(B, N)`` bits in each vessel's bucket (``budget_rate``).
        wants: ``(B, N)`` the policies' decisions for the next update (``TRANSMIT``).
        counts: ``(B, len(COUNTERS), N)`` the messages of the last update, by ``COUNTERS``.
    """

    def __init__(
        self,
        channel: ChannelConfig,
        n: int,
        dt: float,
        schedule: Sequence[tuple[float, np.ndarray]],
        max_steps: int,
        num_envs: int,
        transmit: bool = False,
    ) -> None:
        """
        Args:
            channel: how messages travel.
            n: vessels per formation.
            dt: the control period [s].
            schedule: ``((dwell [s], adjacency (n, n)), …)`` repeated
                periodically; a fixed graph is ``((math.inf, adjacency),)``.
            max_steps: control periods per episode (delays are capped there).
            num_envs: formations ``B``.
            transmit: the vessels' policies decide when to broadcast (``wants``).
        """
        ch = channel
        self.channel: ChannelConfig = ch
        self.dt = dt
        b = num_envs
        self.n, self.num_envs = n, b
        # one ring slot per possible delay in control periods; a message that would
        # arrive after the episode's last step is never seen, so delays are capped there
        self.max_delay_steps = min(math.ceil(ch.max_delay / self.dt - 1e-9), max_steps)
        self.depth = self.max_delay_steps + 1
        self.graphs = np.stack([np.asarray(adjacency, dtype=bool) for _, adjacency in schedule])
        self.ends = np.cumsum([dwell for dwell, _ in schedule])
        self.tdma = ch.tdma_slot is not None
        self.every = ch.slot_steps(self.dt) if self.tdma else ch.period_steps(self.dt)
        self.p_fail = -math.expm1(-ch.failure_rate * self.dt)
        self.p_recover = -math.expm1(-ch.recovery_rate * self.dt)
        self.loss_matrix: Any = np.asarray(ch.loss) if isinstance(ch.loss, tuple) else ch.loss
        shape = (b, n, n)
        self.up = np.zeros(shape, dtype=bool)
        self.has_message = np.zeros(shape, dtype=bool)
        self.held_theta = np.zeros(shape)
        self.held_xdot = np.zeros(shape)
        self.held_time = np.zeros(shape)
        self.failed = np.zeros(shape, dtype=bool)
        self.bad = np.zeros(shape, dtype=bool)
        self.transmitted = np.zeros((b, n), dtype=bool)
        deep = (b, self.depth, n, n)
        self.pend_valid = np.zeros(deep, dtype=bool)
        self.pend_theta = np.zeros(deep)
        self.pend_xdot = np.zeros(deep)
        self.pend_time = np.zeros(deep)
        self.next_arrival = np.full(b, NEVER, dtype=np.int64)
        self.uniforms = BlockStream(b, self.draws_per_link * n * n)
        # who broadcasts: the mode, the last broadcast of each vessel, its token bucket, the counters
        self.mode = TRANSMIT if transmit else (EVENT if ch.event_triggered else PERIODIC)
        self.min_steps, self.heartbeat_steps = ch.event_steps(dt)
        self.threshold = 0.0 if ch.event_threshold is None else float(ch.event_threshold)
        self.refill = float(ch.budget_rate) * dt if ch.has_budget else 0.0
        self.sent_theta = np.full((b, n), np.inf)
        self.sent_xdot = np.zeros((b, n))
        self.sent_time = np.zeros((b, n))
        self.sent_step = np.full((b, n), -NOT_SENT, dtype=np.int64)
        self.tokens = np.full((b, n), ch.bucket)
        self.wants = np.ones((b, n), dtype=bool)
        self.counts = np.zeros((b, len(COUNTERS), n), dtype=np.int64)

    # ------------------------------------------------------------------ draws
    @property
    def draws_per_link(self) -> int:
        """Uniform variates drawn per link and update: failure, Gilbert–Elliott, loss, jitter."""
        ch = self.channel
        return 1 + int(ch.failure_rate > 0 or ch.recovery_rate > 0) + int(ch.burst is not None) + int(ch.jitter > 0)

    def seed(self, b: int, generator: np.random.Generator) -> None:
        """Give formation ``b`` a new stream of uniforms (the first of ``channel_streams``)."""
        self.uniforms.seed(b, generator)

    def draws_at(self, transmitting: np.ndarray) -> np.ndarray:
        """Which formations draw a row of uniforms at a control instant, given ``(m, N)`` transmitters.

        A formation draws one row at an instant when a vessel of it transmits
        (the loss, Gilbert–Elliott and jitter draws of its links) or when
        links can fail (the failure draw of every link); otherwise nothing
        random happens and its stream is left untouched.
        """
        ch = self.channel
        if ch.failure_rate > 0 or ch.recovery_rate > 0:
            return np.ones(len(transmitting), dtype=bool)
        return np.asarray(transmitting.any(axis=1))

    def _instant_uniforms(self, ids: np.ndarray, transmitting: np.ndarray) -> np.ndarray:
        """``(draws_per_link, len(ids), N, N)``: a row of uniforms for each formation that draws
        (``draws_at``); the others' entries are never read (nothing is sent, no link can fail)."""
        need = self.draws_at(transmitting)
        if need.all():
            return self._uniforms(ids)
        out = np.ones((self.draws_per_link, len(ids), self.n, self.n))
        if need.any():
            out[:, need] = self._uniforms(ids[need])
        return out

    def _uniforms(self, ids: np.ndarray) -> np.ndarray:
        """``(draws_per_link, len(ids), N, N)`` uniforms: one row of each formation's stream."""
        rows = self.uniforms.take(ids).reshape(len(ids), self.draws_per_link, self.n, self.n)
        return rows.transpose(1, 0, 2, 3)

    # ----------------------------------------------------------------- update
    def graph_at(self, time: np.ndarray) -> np.ndarray:
        """``(len(time), N, N)`` adjacency of the communication graph at each time [s]."""
        if len(self.graphs) == 1:
            return np.broadcast_to(self.graphs[0], (len(time), self.n, self.n))
        phase = np.mod(np.asarray(time) + 1e-9, self.ends[-1])
        return self.graphs[np.searchsorted(self.ends, phase, side="right")]

    def transmitters(self, steps: np.ndarray) -> np.ndarray:
        """``(len(steps), N)`` which vessels transmit at control instant ``steps``."""
        steps = np.asarray(steps)[:, None]
        if self.tdma:
            return np.mod(steps, self.n * self.every) == np.arange(self.n) * self.every
        return np.broadcast_to(np.mod(steps, self.every) == 0, (len(steps), self.n))

    def reset(self, ids: np.ndarray) -> None:
        """Forget everything of formations ``ids``: no messages, every link live, chains stationary,
        nothing broadcast, full buckets."""
        for arr in (self.up, self.has_message, self.failed, self.transmitted):
            arr[ids] = False
        for arr in (self.held_theta, self.held_xdot, self.held_time, self.sent_xdot, self.sent_time):
            arr[ids] = 0.0
        self.sent_theta[ids] = np.inf
        self.sent_step[ids] = -NOT_SENT
        self.tokens[ids] = self.channel.bucket
        self.pend_valid[ids] = False
        self.next_arrival[ids] = NEVER
        burst = self.channel.burst
        if burst is not None:
            self.bad[ids] = self._uniforms(ids)[0] < burst.p_bad

    def update(
        self,
        ids: np.ndarray,
        steps: np.ndarray,
        time: np.ndarray,
        theta: np.ndarray,
        xdot: np.ndarray,
        positions: np.ndarray,
    ) -> None:
        """One control instant of formations ``ids``: link states, transmissions, arrivals.

        Args:
            ids: ``(m,)`` formation indices.
            steps: ``(m,)`` control periods since reset (0 at reset).
            time: ``(m,)`` time [s].
            theta: ``(m, N)`` measured ``x − D_x`` [m] the vessels transmit.
            xdot: ``(m, N)`` measured inertial ``ẋ`` [m/s] they transmit.
            positions: ``(m, N, 2)`` true positions [m] (for ``range``).
        """
        ch = self.channel
        rows = self._rows(ids)
        steps = np.asarray(steps)
        counts = np.zeros((len(ids), len(COUNTERS), self.n), dtype=np.int64)
        tx = self._broadcasts(rows, steps, np.asarray(time), theta, xdot, counts)
        draws = iter(self._instant_uniforms(ids, tx))
        graph = self.graph_at(time)
        up = graph.copy()
        if math.isfinite(ch.range):
            gap = positions[:, :, None, :] - positions[:, None, :, :]
            up &= in_range(gap[..., 0], gap[..., 1], ch.range)
        if ch.failure_rate > 0 or ch.recovery_rate > 0:
            r = next(draws)
            failed = self.failed[rows]
            fresh = (np.asarray(steps) == 0)[:, None, None]  # every link is live at reset
            failed = np.where(fresh, False, np.where(failed, r >= self.p_recover, r < self.p_fail))
            self.failed[rows] = failed
            up &= ~failed
        self.up[rows] = up
        self.transmitted[rows] = tx
        send = up & tx[:, None, :]
        counts[:, RANGE] = (graph & ~up & tx[:, None, :]).sum(axis=1)
        if ch.burst is not None:
            r = next(draws)
            bad = self.bad[rows]
            moved = np.where(bad, r >= ch.burst.p_bad_to_good, r < ch.burst.p_good_to_bad)
            bad = np.where(send, moved, bad)
            self.bad[rows] = bad
            p_loss: Any = np.where(bad, ch.burst.loss_bad, ch.burst.loss_good)
        else:
            p_loss = self.loss_matrix
        delivered = send & (next(draws) >= p_loss)
        counts[:, DELIVERED] = delivered.sum(axis=1)
        counts[:, LOSS] = (send & ~delivered).sum(axis=1)
        self.counts[rows] = counts
        delay = ch.latency + (ch.jitter * next(draws) if ch.jitter > 0 else 0.0)
        delay_steps = np.ceil(delay / self.dt - 1e-9).astype(np.int64) if ch.max_delay > 0 else 0
        delivered &= delay_steps <= self.max_delay_steps  # later than the episode's end: never seen
        arrival_slot = np.mod(np.asarray(steps)[:, None, None] + delay_steps, self.depth)
        sel_b, sel_j, sel_i = np.nonzero(delivered)
        if sel_b.size:
            slot = np.broadcast_to(arrival_slot, delivered.shape)[sel_b, sel_j, sel_i]
            where = (ids[sel_b], slot, sel_j, sel_i)
            self.pend_valid[where] = True
            self.pend_theta[where] = theta[sel_b, sel_i]
            self.pend_xdot[where] = xdot[sel_b, sel_i]
            self.pend_time[where] = time[sel_b]
            arrival = np.asarray(steps)[sel_b] + np.broadcast_to(delay_steps, delivered.shape)[sel_b, sel_j, sel_i]
            np.minimum.at(self.next_arrival, ids[sel_b], arrival)
        # arrivals at this instant (zero-delay messages sent just now included)
        k = np.mod(steps, self.depth)
        now: tuple[Any, Any] = (rows, int(k[0])) if k.min() == k.max() else (ids, k)  # a view when in step
        arrived = self.pend_valid[now]
        if arrived.any():
            has, held_time = self.has_message[rows], self.held_time[rows]
            newer = arrived & (~has | (self.pend_time[now] > held_time))
            for held, pend in (
                (self.held_theta, self.pend_theta),
                (self.held_xdot, self.pend_xdot),
                (self.held_time, self.pend_time),
            ):
                held[rows] = np.where(newer, pend[now], held[rows])
            self.has_message[rows] = has | newer
            self.pend_valid[now] = False
        self._advance_next_arrival(ids, steps)

    def _broadcasts(
        self, rows: Any, steps: np.ndarray, time: np.ndarray, theta: np.ndarray, xdot: np.ndarray, counts: np.ndarray
    ) -> np.ndarray:
        """``(m, N)`` which vessels broadcast now (module docstring, steps 2-4), recorded as their last
        broadcast; the per-broadcast counters into ``counts``."""
        opportunity = self.transmitters(steps)
        if self.mode == TRANSMIT:  # at reset there is no decision yet: every vessel tries
            attempt = self.wants[rows] | (steps == 0)[:, None]
            clear = attempt & opportunity
        elif self.mode == EVENT:
            error = prediction_error(
                theta, xdot, self.sent_theta[rows], self.sent_xdot[rows], time[:, None] - self.sent_time[rows]
            )
            since = steps[:, None] - self.sent_step[rows]
            attempt = clear = opportunity & event_due(
                error, self.threshold, since, self.min_steps, self.heartbeat_steps
            )
        else:
            attempt = clear = opportunity
        tx = clear
        if self.channel.has_budget:
            bits, bucket = self.channel.message_bits, self.channel.bucket
            tokens = np.where((steps == 0)[:, None], bucket, np.minimum(self.tokens[rows] + self.refill, bucket))
            tx = clear & (tokens >= bits)
            self.tokens[rows] = tokens - bits * tx
        counts[:, ATTEMPTED] = attempt
        counts[:, SENT] = tx
        counts[:, SCHEDULE] = attempt & ~clear
        counts[:, BUDGET] = clear & ~tx
        for held, now in ((self.sent_theta, theta), (self.sent_xdot, xdot), (self.sent_time, time[:, None])):
            held[rows] = np.where(tx, now, held[rows])
        self.sent_step[rows] = np.where(tx, steps[:, None], self.sent_step[rows])
        return np.asarray(tx)

    def _advance_next_arrival(self, ids: np.ndarray, steps: np.ndarray) -> None:
        """After the arrivals at ``steps``: the next instant at which a message of each formation arrives.

        A message in slot ``s`` arrives at ``step + ((s − step) mod depth)``
        (its delay is shorter than ``depth``); ``NEVER`` when none is on
        its way. The compiled channel reads only this ``(B,)`` array at
        instants without arrivals, not the formation's ring of slots.
        """
        due = self.next_arrival[ids] <= steps
        if not due.any():
            return
        f, k = ids[due], steps[due]
        waiting = self.pend_valid[f].any(axis=(2, 3))  # (m, depth)
        when = k[:, None] + np.mod(np.arange(self.depth)[None, :] - k[:, None], self.depth)
        self.next_arrival[f] = np.where(waiting, when, NEVER).min(axis=1)

    def _rows(self, ids: np.ndarray) -> Any:
        """Index of formations ``ids`` (distinct, increasing): a slice (views, no copies) when it is all of them."""
        return slice(None) if len(ids) == self.num_envs else ids

    def slots(
        self, ids: Any, slot_index: np.ndarray, time: np.ndarray, theta: np.ndarray, xdot: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Slot features ``(link, Δθ, Δẋ, age)``, each ``(m, N, N−1)``, of formations ``ids``.

        ``theta``/``xdot`` are the receivers' own measured values now.
        """
        if not isinstance(ids, slice):
            ids = self._rows(np.asarray(ids))
        receivers = np.arange(self.n)[:, None]
        pick = (slice(None), receivers, slot_index)
        linked = (self.up[ids] & self.has_message[ids])[pick].astype(float)
        d_theta = linked * (theta[:, :, None] - self.held_theta[ids][pick])
        d_xdot = linked * (xdot[:, :, None] - self.held_xdot[ids][pick])
        age = linked * (np.asarray(time)[:, None, None] - self.held_time[ids][pick])
        return linked, d_theta, d_xdot, age
