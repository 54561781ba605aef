"""Throughput benchmark against MPE2 and VMAS, measured in one run on one machine.

Example::

    python -m benchmarks.throughput                 # table on stdout, JSON in results/
    python -m benchmarks.throughput --quick         # fewer repeats and sizes, for a smoke check

Cases (random actions, 3 agents, ``force`` level, default scenario settings):

* ``parallel``: our PettingZoo ParallelEnv (one formation) vs MPE2
  ``simple_spread_v3.parallel_env(N=3, continuous_actions=True)``: steps/s,
  dict in, dicts out, resetting when an episode ends.
* ``batched``: our ``MarineFormationVectorEnv``
  (the batched core, with autoreset) at B = 1, 64, 1024, 8192 formations vs
  VMAS ``simple_spread`` on the CPU (``n_agents=3``, continuous actions) at the
  same B: env-steps/s (formation-steps: B per call).
* ``acoustic``, ``radio``: the same two cases with those presets' channels
  (the observations through lossy, delayed TDMA links);
* ``traffic``: the batched env at each B with event-triggered broadcasting
  (``paper``, δ = 0.5), a bandwidth budget (``paper_budget``) and both over
  the acoustic channel (``acoustic_budget``, δ = 0.5), against its ideal links
  in the same run (``--traffic`` runs this case alone);
* ``scaling``: the batched env at B = 256 for n = 3, 8, 20, 50 vessels on a
  random sparse digraph, with ideal links and the ``acoustic`` channel:
  env-steps/s, vessel-steps/s, and the exponent of the cost's growth with n;
* ``jaxmarl``: JaxMARL's MPE ``simple_spread`` (3 agents, continuous
  actions), jit-compiled and vmapped over B on the CPU, timed both as a
  jitted ``lax.scan`` of 100 steps per call (no Python between steps: favours
  JaxMARL) and as one jitted step per Python call (like-for-like);
* peak memory (max RSS of the process that ran the case);
* the arithmetic cost of one vessel-step, counted by running the step on arrays
  that count every elementwise numpy operation (ufunc calls times elements),
  and the fraction of this machine's elementwise throughput (measured here with
  a fused multiply-add kernel on in-cache arrays) that the batched core reaches.

Each case runs in its own subprocess (so that memory peaks and imports do not
mix). Timings are steady state: a warm-up of at least 3 s that also goes
through episode ends (so that the autoreset path has run and been compiled),
then ``--repeats`` timed repeats, reported as the median and the spread
(slowest, quartiles, fastest). Actions are drawn before timing starts. The
first ``step()`` of a fresh process is timed separately, with an empty and
with a filled numba cache. Peers that cannot be imported are reported as such; the
``bench`` extra installs them (``pip install 'marine-formation-env[bench]'``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from marine_formation_env.atomic import atomic_write_text, check_writable
from marine_formation_env.cli import ArgumentParser
from marine_formation_env.provenance import command_line, provenance

__all__ = ["count_vessel_step_ops", "first_step_latency", "main", "run_case", "team_size_scaling"]

BATCH_SIZES = (1, 64, 1024, 8192)
ACTION_POOL = 64  # pre-drawn random actions, cycled


#: Warm-up before timing [s], at least: long enough for every compiled path to have been compiled.
WARMUP_SECONDS = 3.0
#: A case's worker is stopped after this many seconds [s] and reported as unavailable.
CASE_TIMEOUT = 900.0
#: Episode ends (autoresets) that the warm-up must have gone through before timing starts.
WARMUP_RESETS = 2


def _time_steps(
    step: Callable[[int], int], min_seconds: float, repeats: int, warmup_seconds: float = WARMUP_SECONDS
) -> dict[str, Any]:
    """Steady-state steps/s: ``repeats`` timed runs of at least ``min_seconds`` each, after a warm-up.

    ``step(k)`` takes one step and returns how many episode ends (resets) it
    went through. The warm-up lasts at least ``warmup_seconds`` *and* until
    ``WARMUP_RESETS`` resets have happened, so that every code path,
    autoreset included, has run (and been compiled) before timing; a peer
    that never resets (``step`` returning 0) warms up for the time alone.
    Reports the median, the spread (min, quartiles, max) and every repeat.
    """
    count = resets = 0
    start = time.perf_counter()
    deadline = start + 10.0 * max(warmup_seconds, 1.0)  # a peer whose episodes never end stops waiting
    while time.perf_counter() - start < warmup_seconds or (resets < WARMUP_RESETS and time.perf_counter() < deadline):
        resets += step(count)
        count += 1
    warmup = {"steps": count, "resets": resets, "seconds": time.perf_counter() - start}
    rates = []
    for _ in range(repeats):
        done, begin = 0, time.perf_counter()
        while True:  # the clock is read after every step (50 ns): a slow step (a 100-step scan) stops in time
            step(count)
            count += 1
            done += 1
            elapsed = time.perf_counter() - begin
            if elapsed >= min_seconds:
                break
        rates.append(done / elapsed)
    q1, q3 = np.percentile(rates, [25, 75])
    return {
        "steps_per_s": float(np.median(rates)),
        "spread": {"min": float(min(rates)), "q1": float(q1), "q3": float(q3), "max": float(max(rates))},
        "repeats": rates,
        "warmup": warmup,
    }


# ------------------------------------------------------------------ our cases
def _ours_parallel(min_seconds: float, repeats: int, backend: str = "auto", scenario: str = "paper") -> dict[str, Any]:
    from marine_formation_env.env import parallel_env

    env = parallel_env(scenario, action_level="force", backend=backend)
    rng = np.random.default_rng(0)
    pool = [{a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.possible_agents} for _ in range(ACTION_POOL)]
    env.reset(seed=0)
    return _time_parallel_env(env, pool, min_seconds, repeats)


def _time_parallel_env(env: Any, pool: list[dict[str, Any]], min_seconds: float, repeats: int) -> dict[str, Any]:
    """Steady-state steps/s of a PettingZoo ParallelEnv (ours or a peer), resetting when the episode ends."""

    def step(k: int) -> int:
        env.step(pool[k % len(pool)])
        if not env.agents:
            env.reset()
            return 1
        return 0

    return _time_steps(step, min_seconds, repeats)


def _ours_batched(
    b: int,
    min_seconds: float,
    repeats: int,
    backend: str = "auto",
    scenario: str = "paper",
    **overrides: Any,
) -> dict[str, Any]:
    from marine_formation_env.vector import MarineFormationVectorEnv

    env = MarineFormationVectorEnv(num_envs=b, scenario=scenario, action_level="force", backend=backend, **overrides)
    rng = np.random.default_rng(0)
    pool = [rng.uniform(-1, 1, env.action_space.shape).astype(np.float32) for _ in range(8)]
    env.reset(seed=0)

    def step(k: int) -> int:
        _, _, terminated, truncated, _ = env.step(pool[k % len(pool)])
        return int(np.count_nonzero(terminated | truncated))  # reset at the next step (NEXT_STEP autoreset)

    out = _time_steps(step, min_seconds, repeats)
    out["env_steps_per_s"] = out["steps_per_s"] * b
    return out


# ------------------------------------------------------------------- peers
def _mpe2_parallel(min_seconds: float, repeats: int) -> dict[str, Any]:
    from mpe2 import simple_spread_v3

    env = simple_spread_v3.parallel_env(N=3, continuous_actions=True)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = [
        {a: rng.uniform(0, 1, env.action_space(a).shape).astype(np.float32) for a in env.possible_agents}
        for _ in range(ACTION_POOL)
    ]
    return _time_parallel_env(env, pool, min_seconds, repeats)


def _vmas_batched(b: int, min_seconds: float, repeats: int) -> dict[str, Any]:
    import torch
    import vmas

    torch.manual_seed(0)
    env = vmas.make_env("simple_spread", num_envs=b, device="cpu", continuous_actions=True, n_agents=3, seed=0)
    env.reset()
    pool = [[torch.rand(b, 2) * 2.0 - 1.0 for _ in range(3)] for _ in range(8)]

    def step(k: int) -> int:
        env.step(pool[k % len(pool)])  # VMAS does not reset by itself; neither does this loop
        return 0

    out = _time_steps(step, min_seconds, repeats)
    out["env_steps_per_s"] = out["steps_per_s"] * b
    return out


#: Steps per jitted ``lax.scan`` call of the JaxMARL rollout case.
JAX_SCAN_STEPS = 100


def _jaxmarl_batched(b: int, min_seconds: float, repeats: int, scan: bool) -> dict[str, Any]:
    """JaxMARL's MPE ``simple_spread`` (3 agents, continuous actions), jit-compiled and vmapped over ``b``.

    ``scan``: ``JAX_SCAN_STEPS`` steps per call inside ``lax.scan`` (no
    Python between steps: the way JaxMARL is meant to be used, and the fastest
    for it); otherwise one jitted, vmapped step per Python call, as a Python
    training loop steps an env (the like-for-like comparison). JaxMARL resets
    finished episodes inside ``step`` (its own autoreset).
    """
    import jax
    import jax.numpy as jnp
    from jaxmarl import make

    env = make("MPE_simple_spread_v3", num_agents=3, action_type="Continuous")
    agents = env.agents
    space: Any = env.action_space(agents[0])  # a Box with continuous actions (its base class has no shape)
    dim = int(np.prod(space.shape))
    keys = jax.random.split(jax.random.PRNGKey(0), b)
    _, state = jax.vmap(env.reset)(keys)
    rng = np.random.default_rng(0)
    pool = [{a: jnp.asarray(rng.uniform(0.0, 1.0, (b, dim)), dtype=jnp.float32) for a in agents} for _ in range(8)]
    one_step = jax.vmap(env.step, in_axes=(0, 0, 0))

    if scan:

        def rollout(state: Any, key: Any, actions: dict[str, Any]) -> Any:
            def body(carry: Any, _: Any) -> Any:
                state, key = carry
                key, sub = jax.random.split(key)
                _, state, _, _, _ = one_step(jax.random.split(sub, b), state, actions)
                return (state, key), None

            (state, key), _ = jax.lax.scan(body, (state, key), None, length=JAX_SCAN_STEPS)
            return state, key

        run = jax.jit(rollout)
        carry = [state, jax.random.PRNGKey(1)]

        def step(k: int) -> int:
            carry[0], carry[1] = run(carry[0], carry[1], pool[k % len(pool)])
            jax.block_until_ready(carry[0])
            return 0

        out = _time_steps(step, min_seconds, repeats)
        out["steps_per_s"] *= JAX_SCAN_STEPS
        out["spread"] = {key: value * JAX_SCAN_STEPS for key, value in out["spread"].items()}
        out["repeats"] = [value * JAX_SCAN_STEPS for value in out["repeats"]]
    else:
        jitted = jax.jit(one_step)
        holder = [state, jax.random.PRNGKey(1)]

        def step(k: int) -> int:
            holder[1], sub = jax.random.split(holder[1])
            _, holder[0], _, _, _ = jitted(jax.random.split(sub, b), holder[0], pool[k % len(pool)])
            jax.block_until_ready(holder[0])
            return 0

        out = _time_steps(step, min_seconds, repeats)
    out["env_steps_per_s"] = out["steps_per_s"] * b
    return out


def run_case(case: str, b: int, min_seconds: float, repeats: int) -> dict[str, Any]:
    """Run one case in this process and return its measurements (and max RSS)."""
    try:
        if case == "ours_parallel":
            out: dict[str, Any] = _ours_parallel(min_seconds, repeats)
        elif case == "ours_numpy_parallel":
            out = _ours_parallel(min_seconds, repeats, backend="numpy")
        elif case == "ours_numpy_batched":
            out = _ours_batched(b, min_seconds, repeats, backend="numpy")
        elif case == "ours_acoustic_parallel":
            out = _ours_parallel(min_seconds, repeats, scenario="acoustic")
        elif case == "ours_acoustic_batched":
            out = _ours_batched(b, min_seconds, repeats, scenario="acoustic")
        elif case == "ours_radio_parallel":
            out = _ours_parallel(min_seconds, repeats, scenario="radio")
        elif case == "ours_radio_batched":
            out = _ours_batched(b, min_seconds, repeats, scenario="radio")
        elif case == "mpe2_parallel":
            out = _mpe2_parallel(min_seconds, repeats)
        elif case == "ours_batched":
            out = _ours_batched(b, min_seconds, repeats)
        elif case == "vmas_batched":
            out = _vmas_batched(b, min_seconds, repeats)
        elif case == "jaxmarl_scan_batched":
            out = _jaxmarl_batched(b, min_seconds, repeats, scan=True)
        elif case == "jaxmarl_step_batched":
            out = _jaxmarl_batched(b, min_seconds, repeats, scan=False)
        elif case.startswith("traffic_"):
            scenario, overrides = TRAFFIC[case.removeprefix("traffic_")]
            out = _ours_batched(b, min_seconds, repeats, scenario=scenario, **overrides)
        elif case.startswith(("scaling_ideal_", "scaling_acoustic_")):
            scenario, n = ("acoustic" if "acoustic" in case else "paper"), int(case.rsplit("_", 1)[1])
            out = _ours_batched(b, min_seconds, repeats, scenario=scenario, n_vessels=n, topology="random")
            out["vessel_steps_per_s"] = out["env_steps_per_s"] * n
        else:
            raise ValueError(f"unknown case {case!r}")
    except ImportError as err:
        return {"unavailable": f"{type(err).__name__}: {err}"}
    out["max_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


# ------------------------------------------------------------- arithmetic
class _Counter(np.ndarray):
    """An ndarray that counts elementwise operations (ufunc calls × output elements)."""

    ops: dict[str, int] = {}  # noqa: RUF012 - a tally shared by all instances during one count

    def __array_ufunc__(self, ufunc: Any, method: str, *inputs: Any, **kwargs: Any) -> Any:
        args = [np.asarray(x) if isinstance(x, _Counter) else x for x in inputs]
        if "out" in kwargs:
            kwargs["out"] = tuple(np.asarray(o) if isinstance(o, _Counter) else o for o in kwargs["out"])
        result = getattr(ufunc, method)(*args, **kwargs)
        size = int(np.size(result[0] if isinstance(result, tuple) else result))
        _Counter.ops[ufunc.__name__] = _Counter.ops.get(ufunc.__name__, 0) + size
        if isinstance(result, np.ndarray) and method == "__call__":
            return result.view(_Counter)
        return result


def count_vessel_step_ops(level: str = "force") -> dict[str, Any]:
    """Elementwise numpy operations per vessel-step of the core's integration (dynamics + inner loops).

    Counts the RK4 substeps of one control period (every stage evaluates the
    vessel ODE and, below the ``force`` level, the inner controllers), for
    one formation of three vessels, divided by three.
    """
    from marine_formation_env.actions import physical_commands
    from marine_formation_env.core import FormationCore
    from marine_formation_env.dynamics import rk4_step
    from marine_formation_env.scenarios import make_config

    core = FormationCore(make_config("paper", action_level=level), num_envs=1)
    core.reset(core.config.start_state)
    commands = physical_commands(core.config, np.zeros((1, 3, core.action_dim)))
    rhs = core.closed_loop(commands)
    state: np.ndarray = core.state.view(_Counter)
    h = core.config.dt / core.config.substeps
    _Counter.ops = {}
    for k in range(core.config.substeps):
        state = rk4_step(rhs, state, h, k * h)
    per_vessel = {name: n / 3.0 for name, n in _Counter.ops.items()}
    transcendental = sum(v for k, v in per_vessel.items() if k in ("sin", "cos", "arctan", "sqrt", "hypot"))
    return {
        "level": level,
        "substeps": core.config.substeps,
        "ops_per_vessel_step": float(sum(per_vessel.values())),
        "transcendental_per_vessel_step": float(transcendental),
        "by_ufunc": per_vessel,
    }


def elementwise_peak(seconds: float = 0.5) -> float:
    """This machine's numpy elementwise throughput [ops/s]: ``c = a*b + c`` on in-cache float64 arrays."""
    n = 16384
    a, b, c = np.random.default_rng(0).random((3, n))
    tmp = np.empty(n)
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(200):
            np.multiply(a, b, out=tmp)
            np.add(tmp, c, out=c)
        count += 200
        c *= 0.5
    return 2.0 * n * count / (time.perf_counter() - start)


# ------------------------------------------------------------ team size
#: Team sizes of the scaling case, and its number of formations.
TEAM_SIZES = (3, 8, 20, 50)
SCALING_B = 256


#: The ``traffic`` cases: (scenario, overrides); ``ideal`` is the paper's links, the reference of the ratios.
TRAFFIC: dict[str, tuple[str, dict[str, Any]]] = {
    "ideal": ("paper", {}),
    "event": ("paper", {"channel": {"event_threshold": 0.5}}),
    "budget": ("paper_budget", {}),
    "acoustic_event_budget": ("acoustic_budget", {"channel": {"event_threshold": 0.5}}),
    "transmit": ("paper_budget", {"transmit": True}),
}


def traffic_throughput(batch_sizes: Sequence[int], min_seconds: float, repeats: int) -> dict[str, Any]:
    """env-steps/s of the batched env with event triggering and budgets (``TRAFFIC``) at each B, each case in
    its own subprocess, and each rate over the ideal links' of the same run (``over_ideal``)."""
    out: dict[str, Any] = {}
    for b in batch_sizes:
        row = {name: _subprocess_case(f"traffic_{name}", b, min_seconds, repeats) for name in TRAFFIC}
        ideal = row["ideal"].get("env_steps_per_s")
        for entry in row.values():
            if ideal and "env_steps_per_s" in entry:
                entry["over_ideal"] = entry["env_steps_per_s"] / ideal
        out[str(b)] = row
    return out


def team_size_scaling(min_seconds: float, repeats: int, sizes: Sequence[int] = TEAM_SIZES) -> dict[str, Any]:
    """env-steps/s and vessel-steps/s at B = ``SCALING_B`` for n vessels on a random sparse digraph.

    Ideal links and the ``acoustic`` channel. The cost of one env-step grows
    with n (the observation holds n − 1 slots per vessel, so it is O(n²) per
    formation); ``exponent`` is the least-squares slope of log(seconds per
    env-step) against log(n).
    """
    out: dict[str, Any] = {"b": SCALING_B, "sizes": list(sizes)}
    for links in ("ideal", "acoustic"):
        rows: dict[str, Any] = {
            str(n): _subprocess_case(f"scaling_{links}_{n}", SCALING_B, min_seconds, repeats) for n in sizes
        }
        measured = [(int(n), row["env_steps_per_s"]) for n, row in rows.items() if "env_steps_per_s" in row]
        if len(measured) >= 2:
            ns, rates = np.array(measured, dtype=float).T
            rows["exponent"] = float(np.polyfit(np.log(ns), np.log(1.0 / rates), 1)[0])
        out[links] = rows
    return out


# ------------------------------------------------------------ first step
FIRST_STEP = """
import time
start = time.perf_counter()
import numpy as np
import marine_formation_env
env = marine_formation_env.parallel_env("paper", action_level="force", backend="{backend}")
env.reset(seed=0)
env.step({{a: np.zeros(2, dtype=np.float32) for a in env.agents}})
print(time.perf_counter() - start)
"""


def first_step_latency() -> dict[str, float]:
    """Seconds from a fresh interpreter to the first ``step()`` returning (import, construction, reset, step).

    ``numba_cold``: numba compiles the kernel (an empty on-disk cache);
    ``numba_warm``: the same cache, now filled, as a user's second run sees it;
    ``numpy``: the reference backend, nothing to compile.
    """
    import tempfile

    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
        for label, backend in (("numba_cold", "numba"), ("numba_warm", "numba"), ("numpy", "numpy")):
            proc = subprocess.run(
                [sys.executable, "-c", FIRST_STEP.format(backend=backend)],
                capture_output=True,
                text=True,
                env=env,
                check=False,
            )
            if proc.returncode != 0:
                raise RuntimeError(f"first-step run ({label}) failed: {proc.stderr.strip().splitlines()[-1:]}")
            out[label] = float(proc.stdout.strip().splitlines()[-1])
    return out


# ------------------------------------------------------------------- driver
def _subprocess_case(case: str, b: int, min_seconds: float, repeats: int) -> dict[str, Any]:
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.throughput",
        "--worker",
        case,
        str(b),
        str(min_seconds),
        str(repeats),
    ]
    env = {**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False, timeout=CASE_TIMEOUT)
    except subprocess.TimeoutExpired:
        return {"unavailable": f"worker stopped after {CASE_TIMEOUT:.0f} s (case timeout)"}
    if proc.returncode != 0:
        return {"unavailable": f"worker failed: {proc.stderr.strip().splitlines()[-1:]}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def run_benchmark(batch_sizes: Sequence[int], min_seconds: float, repeats: int) -> dict[str, Any]:
    """All cases, each in a subprocess; returns the JSON-friendly report."""
    report: dict[str, Any] = {
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "numpy": np.__version__,
        },
        "settings": {"min_seconds": min_seconds, "repeats": repeats, "level": "force", "vessels": 3},
        "parallel": {
            "ours": _subprocess_case("ours_parallel", 1, min_seconds, repeats),
            "ours_numpy": _subprocess_case("ours_numpy_parallel", 1, min_seconds, repeats),
            "ours_acoustic": _subprocess_case("ours_acoustic_parallel", 1, min_seconds, repeats),
            "ours_radio": _subprocess_case("ours_radio_parallel", 1, min_seconds, repeats),
            "mpe2": _subprocess_case("mpe2_parallel", 1, min_seconds, repeats),
        },
        "batched": {},
    }
    for b in batch_sizes:
        report["batched"][str(b)] = {
            "ours": _subprocess_case("ours_batched", b, min_seconds, repeats),
            "ours_numpy": _subprocess_case("ours_numpy_batched", b, min_seconds, repeats),
            "ours_acoustic": _subprocess_case("ours_acoustic_batched", b, min_seconds, repeats),
            "ours_radio": _subprocess_case("ours_radio_batched", b, min_seconds, repeats),
            "vmas": _subprocess_case("vmas_batched", b, min_seconds, repeats),
            "jaxmarl_scan": _subprocess_case("jaxmarl_scan_batched", b, min_seconds, repeats),
            "jaxmarl_step": _subprocess_case("jaxmarl_step_batched", b, min_seconds, repeats),
        }
    report["traffic"] = traffic_throughput(batch_sizes, min_seconds, repeats)
    report["scaling"] = team_size_scaling(min_seconds, repeats)
    report["first_step_seconds"] = first_step_latency()
    ops = count_vessel_step_ops("force")
    peak = elementwise_peak()
    report["arithmetic"] = {**ops, "elementwise_peak_ops_per_s": peak}
    for row in report["batched"].values():
        ours = row["ours"]
        for links in ("ours", "ours_acoustic", "ours_radio"):  # the channel's own work is not counted
            if "env_steps_per_s" in row[links]:
                vessel_steps = row[links]["env_steps_per_s"] * 3
                row[links]["fraction_of_elementwise_peak"] = vessel_steps * ops["ops_per_vessel_step"] / peak
        if "env_steps_per_s" in ours and "env_steps_per_s" in row["vmas"]:
            row["ratio_ours_over_vmas"] = ours["env_steps_per_s"] / row["vmas"]["env_steps_per_s"]
    par = report["parallel"]
    if "steps_per_s" in par["ours"] and "steps_per_s" in par["mpe2"]:
        par["ratio_ours_over_mpe2"] = par["ours"]["steps_per_s"] / par["mpe2"]["steps_per_s"]
    return report


def _rate(entry: dict[str, Any], key: str) -> str:
    """The median rate and, in brackets, the slowest and fastest repeat."""
    if key not in entry:
        return f"n/a ({entry.get('unavailable', '?')})"
    scale = entry[key] / entry["steps_per_s"]  # env-steps per step (B), or 1
    low, high = entry["spread"]["min"] * scale, entry["spread"]["max"] * scale
    return f"{entry[key]:,.0f} [{low:,.0f}–{high:,.0f}]"


def format_traffic(report: dict[str, Any]) -> list[str]:
    """The ``traffic`` case's table (none without it)."""
    traffic = report.get("traffic")
    if not traffic:
        return []
    names = [name for name in TRAFFIC if name != "ideal"]
    lines = [
        "",
        "Event-triggered broadcasting and budgets (random force actions; `/ ideal`: over the ideal links of the "
        "same run): `event` is `paper` with δ = 0.5, `budget` is `paper_budget`, `acoustic_event_budget` is "
        "`acoustic_budget` with δ = 0.5, `transmit` is `paper_budget` with the `transmit` action (random, so "
        "each vessel tries at about half of the periods) and its three observation entries:",
        "",
        "| B | ideal links [env-steps/s] | " + " | ".join(f"{n} [env-steps/s] | {n} / ideal" for n in names) + " |",
        "|---|---|" + "---|---|" * len(names),
    ]
    for b, row in traffic.items():
        cells = []
        for name in names:
            entry = row[name]
            over = f"{entry['over_ideal']:.2f}" if "over_ideal" in entry else "n/a"
            cells.append(f"{_rate(entry, 'env_steps_per_s')} | {over}")
        lines.append(f"| {b} | {_rate(row['ideal'], 'env_steps_per_s')} | " + " | ".join(cells) + " |")
    return lines


def format_report(report: dict[str, Any]) -> str:
    """The report as a Markdown table."""

    rate = _rate

    def mem(entry: dict[str, Any]) -> str:
        return f"{entry['max_rss_mb']:.0f}" if "max_rss_mb" in entry else "n/a"

    par = report["parallel"]

    def ratio(a: dict[str, Any], b: dict[str, Any], key: str) -> str:
        return f"{a[key] / b[key]:.2f}" if key in a and key in b else "n/a"

    # (label, our measurements, the peer's, the rate key): one row of each table per case
    cases = [("ParallelEnv vs MPE2 simple_spread_v3", par, par["mpe2"], "steps_per_s")]
    cases += [
        (f"batched B = {b} vs VMAS simple_spread (env-steps/s)", row, row["vmas"], "env_steps_per_s")
        for b, row in report["batched"].items()
    ]
    lines = [
        "| case | ours [steps/s] | peer [steps/s] | ours / peer | ours, numpy backend | numpy / peer "
        "| ours peak RSS [MB] | peer peak RSS [MB] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, ours, peer, key in cases:
        lines.append(
            f"| {label} | {rate(ours['ours'], key)} | {rate(peer, key)} | {ratio(ours['ours'], peer, key)} | "
            f"{rate(ours['ours_numpy'], key)} | {ratio(ours['ours_numpy'], peer, key)} | {mem(ours['ours'])} | "
            f"{mem(peer)} |"
        )
    lines += [
        "",
        "Against JaxMARL's MPE `simple_spread` (jit + vmap on the CPU). `scan`: 100 steps per jitted `lax.scan` "
        "call, no Python between steps, which favours JaxMARL; `step`: one jitted vmapped step per Python call, "
        "like ours:",
        "",
        "| B | ours [env-steps/s] | JaxMARL scan | ours / scan | JaxMARL step | ours / step |",
        "|---|---|---|---|---|---|",
    ]
    for b, row in report["batched"].items():
        scan, step = row.get("jaxmarl_scan", {}), row.get("jaxmarl_step", {})
        key = "env_steps_per_s"
        lines.append(
            f"| {b} | {rate(row['ours'], key)} | {rate(scan, key)} | {ratio(row['ours'], scan, key)} | "
            f"{rate(step, key)} | {ratio(row['ours'], step, key)} |"
        )
    lines += [
        "",
        "The `acoustic` (TDMA, latency with jitter, bursty loss, range) and `radio` (TDMA, loss, latency, range) "
        "channels, observations through the channel; `/ peer`: against the peer's ideal links:",
        "",
        "| case | ideal links [steps/s] | acoustic [steps/s] | acoustic / ideal | acoustic / peer "
        "| radio [steps/s] | radio / ideal | radio / peer |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, ours, peer, key in cases:
        acoustic, radio = ours["ours_acoustic"], ours.get("ours_radio", {})
        lines.append(
            f"| {label} | {rate(ours['ours'], key)} | {rate(acoustic, key)} | "
            f"{ratio(acoustic, ours['ours'], key)} | {ratio(acoustic, peer, key)} | {rate(radio, key)} | "
            f"{ratio(radio, ours['ours'], key)} | {ratio(radio, peer, key)} |"
        )
    lines += format_traffic(report)
    scaling = report.get("scaling")
    if scaling:
        lines += [
            "",
            f"Team size (B = {scaling['b']} formations, random sparse digraph, random force actions):",
            "",
            "| n | ideal env-steps/s | ideal vessel-steps/s | acoustic env-steps/s | acoustic vessel-steps/s |",
            "|---|---|---|---|---|",
        ]
        for n in scaling["sizes"]:
            ideal, acoustic = scaling["ideal"][str(n)], scaling["acoustic"][str(n)]
            lines.append(
                f"| {n} | {rate(ideal, 'env_steps_per_s')} | {rate(ideal, 'vessel_steps_per_s')} | "
                f"{rate(acoustic, 'env_steps_per_s')} | {rate(acoustic, 'vessel_steps_per_s')} |"
            )
        exponents = [
            f"{links} {scaling[links]['exponent']:.2f}"
            for links in ("ideal", "acoustic")
            if "exponent" in scaling[links]
        ]
        lines += ["", f"Cost per env-step grows as n^k with k = {', '.join(exponents)} (least squares over n)."]
    first = report.get("first_step_seconds")
    if first:
        lines += [
            "",
            "First `step()` of a fresh process (import, construction, reset, step) [s]: "
            f"numba with an empty cache {first['numba_cold']:.2f}, with the cache filled {first['numba_warm']:.2f}, "
            f"numpy backend {first['numpy']:.2f}.",
        ]
    lines += [
        "",
        "Rates are medians of the timed repeats after a warm-up through episode ends; in brackets the "
        "slowest and the fastest repeat.",
    ]
    ar = report["arithmetic"]
    lines.append("")
    lines.append(
        f"One vessel-step at the force level ({ar['substeps']} RK4 substep(s)): "
        f"{ar['ops_per_vessel_step']:.0f} elementwise ops ({ar['transcendental_per_vessel_step']:.0f} of them "
        f"sin/cos/atan). Elementwise peak of this machine: {ar['elementwise_peak_ops_per_s'] / 1e9:.2f} Gop/s."
    )
    for b, row in report["batched"].items():
        fractions = [
            f"{name} {row[links]['fraction_of_elementwise_peak']:.1%}"
            for name, links in (("ideal links", "ours"), ("acoustic", "ours_acoustic"), ("radio", "ours_radio"))
            if "fraction_of_elementwise_peak" in row.get(links, {})
        ]
        if fractions:
            lines.append(f"B = {b}: the batched core's model arithmetic runs at {', '.join(fractions)} of it.")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m benchmarks.throughput", description=__doc__.split("\n\n")[0])
    parser.add_argument("--worker", nargs=4, metavar=("CASE", "B", "SECONDS", "REPEATS"), help=argparse.SUPPRESS)
    parser.add_argument("--batch-sizes", type=int, nargs="+", default=list(BATCH_SIZES))
    parser.add_argument("--seconds", type=float, default=2.0, help="minimum seconds per timing repeat (default 2)")
    parser.add_argument("--repeats", type=int, default=5, help="timing repeats per case; the median is used")
    parser.add_argument("--quick", action="store_true", help="B = 1, 64 only, 0.5 s × 3 repeats")
    parser.add_argument("--json", type=Path, default=Path("results/throughput.json"))
    parser.add_argument("--format", type=Path, metavar="JSON", help="only print the tables of a saved report")
    parser.add_argument("--traffic", action="store_true", help="only the traffic case (event triggering, budgets)")
    args = parser.parse_args(argv)
    if args.format:
        try:
            saved = json.loads(args.format.read_text())
            print("\n".join(format_traffic(saved)).strip() if "parallel" not in saved else format_report(saved))
        except (OSError, ValueError, KeyError) as err:
            parser.error(f"--format {args.format}: not a readable report ({type(err).__name__}: {err})")
        return 0
    if args.worker:
        case, b, seconds, repeats = args.worker
        print(json.dumps(run_case(case, int(b), float(seconds), int(repeats))))
        return 0
    if args.quick:
        args.batch_sizes, args.seconds, args.repeats = [1, 64], 0.5, 3
    path = check_writable(args.json, "--json")
    if args.traffic:
        report = {"traffic": traffic_throughput(args.batch_sizes, args.seconds, args.repeats)}
    else:
        report = run_benchmark(args.batch_sizes, args.seconds, args.repeats)
    report["provenance"] = provenance(command_line("python -m benchmarks.throughput", argv))
    atomic_write_text(path, json.dumps(report, indent=2))  # first: the measurements outlive a formatting error
    print("\n".join(format_traffic(report)).strip() if args.traffic else format_report(report))
    print(f"\nwritten {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
