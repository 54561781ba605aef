"""Malformed input is refused with a clear error that names the field and the value, never silently.

One test per input of the hardening issue, front end by front end: the
ParallelEnv, the gymnasium view and the vector env refuse (or accept) the
same thing the same way. The command-line tools are run as a user runs them:
one line on stderr naming the value, exit status 2, no traceback. A
property-based test feeds values of the wrong type to every scenario field.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import marine_formation_env
from marine_formation_env import ENV_ID, ConfigError, ScenarioConfig
from marine_formation_env.scenarios import config_from_dict, make_config
from marine_formation_env.vector import MarineFormationVectorEnv

pytestmark = pytest.mark.backend_independent

ROOT = Path(__file__).resolve().parents[1]


def parallel(**overrides):
    return marine_formation_env.parallel_env("paper", **overrides)


def gym_view(**overrides):
    return gymnasium.make(ENV_ID, disable_env_checker=True, **overrides).unwrapped


def vector(num_envs=2, **overrides):
    return MarineFormationVectorEnv(num_envs, "paper", **overrides)


FRONT_ENDS = {"parallel": parallel, "gym": gym_view, "vector": vector}


# --------------------------------------------------------------------------- configuration


def test_topology_schedule_dwell_must_be_whole_control_periods():
    # accepted before: 0.4 s at dt 0.5 never delivered a link in 800 steps
    with pytest.raises(ConfigError, match=r"topology_schedule\[0\] dwell = 0\.4 s must be a whole number.*dt = 0\.5"):
        make_config("paper", topology=None, topology_schedule=[(0.4, np.zeros((3, 3))), (0.1, "paper")])
    with pytest.raises(ConfigError, match=r"topology_schedule\[1\] dwell = 0\.25"):
        make_config("paper", topology=None, topology_schedule=[(1.0, "chain"), (0.25, "paper")])
    # whole multiples are fine, at any dt
    cfg = make_config("paper", topology=None, topology_schedule=[(1.0, "chain"), (0.3, "paper")], dt=0.1)
    assert [dwell for dwell, _ in cfg.topology_schedule] == [1.0, 0.3]


@pytest.mark.parametrize("value", ["no", "False", 1, 0.0, None])
def test_terminal_penalty_must_be_a_boolean(value):
    with pytest.raises(ConfigError, match=rf"reward\.terminal_penalty must be True or False, got {value!r}"):
        make_config("paper", reward={"terminal_penalty": value})
    assert make_config("paper", reward={"terminal_penalty": False}).reward.terminal_penalty is False


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("fine_share", 1.5, "a share in [0, 1]"),
        ("fine_share", -0.1, "≥ 0"),
        ("fine_share", float("nan"), "finite number"),
        ("fine_scale", 0.0, "> 0"),
        ("fine_scale", -1.0, "> 0"),
        ("fine_scale", "1", "finite number"),
        ("sigma_cross_track", 0.0, "> 0"),
        ("sigma_heading", -0.2, "> 0"),
        ("sigma_speed", float("inf"), "finite number"),
        ("cross_track", -1.0, "≥ 0"),
    ],
)
def test_the_reward_weights_scales_and_fine_share_are_checked(field, value, message):
    pattern = rf"reward\.{field} must be .*{re.escape(message)}.*got {re.escape(repr(value))}"
    with pytest.raises(ConfigError, match=pattern):
        make_config("paper", reward={field: value})


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("speed", "must be a list of term names"),
        (3, "must be a list of term names"),
        (["drift"], "unknown term 'drift'"),
        (["speed", "speed"], "names a term twice"),
    ],
)
def test_the_fine_reward_terms_are_checked(value, message):
    with pytest.raises(ConfigError, match=rf"reward\.fine_terms.*{re.escape(message)}"):
        make_config("paper", reward={"fine_share": 0.3, "fine_terms": value})


@pytest.mark.parametrize("value", ["x", 1.5, -1, True, None])
def test_topology_seed_must_be_a_whole_number(value):
    with pytest.raises(ConfigError, match=rf"topology_seed must be a whole number ≥ 0, got {re.escape(repr(value))}"):
        make_config("paper", n_vessels=5, topology="random", topology_seed=value)


def test_topology_seed_accepts_numpy_integers():
    a = make_config("paper", n_vessels=5, topology="random", topology_seed=np.int64(3))
    b = make_config("paper", n_vessels=5, topology="random", topology_seed=3)
    assert a.topology_seed == 3 and type(a.topology_seed) is int
    assert np.array_equal(a.graph.adjacency, b.graph.adjacency)


def test_workspace_that_excludes_the_initial_state_is_refused():
    # accepted before: every episode ended at step 1
    with pytest.raises(ConfigError, match=r"vessel_0 starts at x = -50 m, outside the workspace: x ∈ \[0, 5000\] m"):
        make_config("paper", workspace=(0.0, 5000.0, -300.0, 300.0))
    with pytest.raises(ConfigError, match=r"vessel_1 starts at y = 30 m, outside the workspace: y ∈ \[-25, 25\] m"):
        make_config("paper", workspace=(-500.0, 5000.0, -25.0, 25.0))


def test_workspace_that_initial_noise_can_leave_is_refused():
    with pytest.raises(ConfigError, match=r"vessel_0 starts at y = 60 m \(nominal 20 ± init_noise 40\)"):
        make_config("paper", init_noise={"y": 40.0}, workspace=(-500.0, 5000.0, -50.0, 50.0))


def test_vessels_closer_than_the_safety_distance_are_refused():
    x0 = np.array([[0.0, 50.0, 0, 5, 0, 0], [3.0, 49.0, 0, 5, 0, 0], [-100.0, -50.0, 0, 5, 0, 0]])
    with pytest.raises(ConfigError, match=r"vessel_0 and vessel_1 start 3\.16228 m apart, closer than safety_distance"):
        make_config("paper", initial_state=x0, safety_distance=5.0)


def test_initial_speed_outside_the_envelope_is_refused():
    x0 = np.array(make_config("paper").initial_state)
    x0[2, 3] = 20.0
    with pytest.raises(ConfigError, match=r"vessel_2 starts at u = 20 m/s, outside the envelope \|u\| ≤ max_speed"):
        make_config("paper", initial_state=x0)


# --------------------------------------------------------------------------- seeds


@pytest.mark.parametrize("front", list(FRONT_ENDS))
@pytest.mark.parametrize(
    ("seed", "error", "message"),
    [
        (1.5, TypeError, r"seed must be a whole number ≥ 0 or None, got 1\.5 \(float\)"),
        ("x", TypeError, r"seed must be a whole number ≥ 0 or None, got 'x' \(str\)"),
        (True, TypeError, r"got True \(bool\)"),
        (-5, ValueError, r"seed must be a whole number ≥ 0 or None, got -5"),
    ],
)
def test_bad_seeds_are_refused_by_every_front_end(front, seed, error, message):
    env = FRONT_ENDS[front]()
    with pytest.raises(error, match=message):
        env.reset(seed=seed)
    with pytest.raises(error, match=message.replace("seed must", "channel_seed must")):
        env.reset(seed=0, options={"channel_seed": seed})


def test_vector_env_refuses_bad_entries_of_a_seed_list():
    env = vector(2)
    with pytest.raises(TypeError, match=r"seed\[0\] must be a whole number ≥ 0 or None, got 1\.5"):
        env.reset(seed=[1.5, 2])
    with pytest.raises(ValueError, match=r"seed needs a whole number or a list of 2 seeds"):
        env.reset(seed=[1, 2, 3])


@pytest.mark.parametrize("front", list(FRONT_ENDS))
def test_numpy_integer_seeds_are_accepted_and_equal_python_ints(front):
    make = FRONT_ENDS[front]  # noise and a lossy channel, so that both seeds matter
    a = make(init_noise={"x": 10.0}, channel={"loss": 0.5})
    b = make(init_noise={"x": 10.0}, channel={"loss": 0.5})
    obs_a, _ = a.reset(seed=np.int64(3), options={"channel_seed": np.uint16(9)})
    obs_b, _ = b.reset(seed=3, options={"channel_seed": 9})
    if isinstance(obs_a, dict):
        obs_a, obs_b = np.stack(list(obs_a.values())), np.stack(list(obs_b.values()))
    assert np.array_equal(obs_a, obs_b)


# --------------------------------------------------------------------------- reset options


@pytest.mark.parametrize("front", list(FRONT_ENDS))
def test_unknown_reset_options_warn_the_same_way_everywhere(front):
    env = FRONT_ENDS[front]()
    with pytest.warns(UserWarning, match=r"reset ignores unknown option\(s\) \['colour'\]; known options"):
        env.reset(seed=0, options={"colour": "red"})


@pytest.mark.parametrize("front", list(FRONT_ENDS))
@pytest.mark.parametrize("options", [[1], "initial_state", 3])
def test_reset_options_must_be_a_dict(front, options):
    env = FRONT_ENDS[front]()
    with pytest.raises(TypeError, match=rf"reset options must be a dict \(or None\), got {re.escape(repr(options))}"):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("front", list(FRONT_ENDS))
def test_known_reset_options_raise_no_warning(front):
    env = FRONT_ENDS[front]()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env.reset(seed=0, options={"channel_seed": 1, "initial_state": make_config("paper").initial_state})


# --------------------------------------------------------------------------- strings and bad initial states


@pytest.mark.parametrize("front", list(FRONT_ENDS))
def test_strings_in_the_initial_state_are_refused(front):
    env = FRONT_ENDS[front]()
    x0 = make_config("paper").initial_state.tolist()
    x0[1][2] = "north"
    with pytest.raises(TypeError, match=r"initial_state must be a numeric array, got .*'north'"):
        env.reset(options={"initial_state": x0})
    with pytest.raises(TypeError, match=r"initial_state must be numeric, got the string 'abc'"):
        env.reset(options={"initial_state": "abc"})


def test_strings_in_actions_are_refused():
    par = parallel()
    par.reset(seed=0)
    with pytest.raises(ValueError, match=r"action of vessel_1 must be numeric, got 'fast'"):
        par.step({"vessel_0": [0.0], "vessel_1": "fast", "vessel_2": [0.0]})
    gym_env = gym_view()
    gym_env.reset(seed=0)
    with pytest.raises(TypeError, match=r"action must be a numeric array, got \['fast', 0\.0, 0\.0\]"):
        gym_env.step(["fast", 0.0, 0.0])
    venv = vector(2)
    venv.reset(seed=0)
    with pytest.raises(TypeError, match=r"actions must be a numeric array"):
        venv.step([["a", "b", "c"], [0.0, 0.0, 0.0]])
    core = venv.core
    with pytest.raises(TypeError, match=r"actions must be numeric, got the string 'x'"):
        core.step("x")


@pytest.mark.parametrize("front", list(FRONT_ENDS))
def test_initial_state_that_ends_the_episode_at_once_is_refused_at_reset(front):
    env = FRONT_ENDS[front](safety_distance=5.0)
    x0 = np.array(make_config("paper").initial_state)
    outside = x0.copy()
    outside[2, 1] = 900.0
    with pytest.raises(ValueError, match=r"vessel_2 starts at y = 900 m, outside the workspace: y ∈ \[-300, 300\] m"):
        env.reset(options={"initial_state": outside})
    close = x0.copy()
    close[1, :2] = close[0, :2] + [1.0, 1.0]
    with pytest.raises(ValueError, match=r"vessel_0 and vessel_1 start 1\.41421 m apart, closer than safety_distance"):
        env.reset(options={"initial_state": close})
    spinning = x0.copy()
    spinning[0, 5] = 2.0
    with pytest.raises(ValueError, match=r"vessel_0 starts at r = 2 rad/s, outside the envelope \|r\| ≤ max_yaw_rate"):
        env.reset(options={"initial_state": spinning})


def test_vector_env_names_the_formation_of_a_bad_initial_state():
    env = vector(3, safety_distance=5.0)
    x0 = np.repeat(np.array(make_config("paper").initial_state)[None], 3, axis=0)
    x0[2, 0, 0] = -1e5
    message = r"initial_state\[2\]: vessel_0 starts at x = -100000 m, outside the workspace"
    with pytest.raises(ValueError, match=message):
        env.reset(options={"initial_state": x0})


def test_refused_reset_changes_nothing():
    env = parallel(init_noise={"x": 20.0})
    env.reset(seed=4)
    state = env.vessel_states
    with pytest.raises(TypeError):
        env.reset(seed=1.5)
    with pytest.raises(ValueError):
        env.reset(seed=7, options={"initial_state": np.full((3, 6), np.inf)})
    assert np.array_equal(env.vessel_states, state)
    # the generator was not reseeded by the refused calls: the next episode is the one after seed 4's first
    fresh = parallel(init_noise={"x": 20.0})
    fresh.reset(seed=4)
    fresh.reset()
    env.reset()
    assert np.array_equal(env.vessel_states, fresh.vessel_states)


# --------------------------------------------------------------------------- command-line tools


def run_cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    env = {"MARINE_FORMATION_BACKEND": "numpy", "PATH": "/usr/bin:/bin"}
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=300)


def assert_one_line_error(result: subprocess.CompletedProcess[str], *fragments: str) -> str:
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--seed", "-5"], ["--seed", "got -5"]),
        (["--seed", "x"], ["--seed", "got 'x'"]),
        (["--episodes", "0"], ["--episodes", "got 0"]),
        (["--policy", "reference:warp"], ["'warp'"]),
        (["--set", "horizon=soon"], ["horizon", "'soon'"]),
        (["--set", "channel.loss=2"], ["channel.loss", "got 2"]),
    ],
)
def test_evaluate_cli_errors_are_one_line(args, fragments):
    assert_one_line_error(run_cli("-m", "baselines.evaluate", "--quiet", *args), *fragments)


def test_evaluate_refuses_an_unwritable_output_before_evaluating(tmp_path, monkeypatch, capsys):
    from baselines import evaluate as evaluate_module

    def must_not_run(*args, **kwargs):
        raise AssertionError("the evaluation ran before the output path was checked")

    monkeypatch.setattr(evaluate_module, "evaluate", must_not_run)
    blocker = tmp_path / "file"
    blocker.write_text("")
    for flag in ("--json", "--save-trajectory", "--plot"):
        with pytest.raises(SystemExit) as exit_info:
            evaluate_module.main(["--quiet", flag, str(blocker / "out.x")])
        assert exit_info.value.code == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and flag in err and "cannot be written" in err and str(blocker) in err
    with pytest.raises(SystemExit):
        evaluate_module.main(["--quiet", "--json", str(tmp_path)])
    assert "is a folder" in capsys.readouterr().err


def test_evaluate_writes_outputs_whole(tmp_path):
    out = tmp_path / "deep" / "r"
    result = run_cli(
        "-m", "baselines.evaluate", "--quiet", "--set", "horizon=5", "--json", f"{out}.json",
        "--save-trajectory", f"{out}.npz",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    report = json.loads(Path(f"{out}.json").read_text())
    assert report["policies"]["reference"]["episodes"][0]["seed"] == 0
    assert np.load(f"{out}.npz")["state"].shape == (11, 3, 6)
    assert sorted(p.name for p in out.parent.iterdir()) == ["r.json", "r.npz"]  # no temporary file left


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory):
    """A run folder as training.train writes it, with an untrained tiny PPO (loading is what is tested)."""
    pytest.importorskip("stable_baselines3")
    import yaml
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from training.vec_env import SharedPolicyVecEnv

    folder = tmp_path_factory.mktemp("run")
    kwargs = {"action_level": "speed", "horizon": 5.0}
    venv = VecNormalize(SharedPolicyVecEnv(1, "paper", **kwargs))
    PPO("MlpPolicy", venv, n_steps=8, batch_size=8, device="cpu").save(folder / "model.zip")
    venv.save(str(folder / "vecnormalize.pkl"))
    config = {"trainer": "sb3", "env_id": ENV_ID, "seed": 0, "algo": "ppo", "scenario": "paper", "env_kwargs": kwargs}
    (folder / "config.yaml").write_text(yaml.safe_dump(config))
    return folder


def _truncated_copy(src: Path, dst: Path, broken: str) -> Path:
    dst.mkdir()
    for path in src.iterdir():
        data = path.read_bytes()
        (dst / path.name).write_bytes(data[: len(data) // 2] if path.name == broken else data)
    return dst


@pytest.mark.slow
@pytest.mark.parametrize("broken", ["model.zip", "vecnormalize.pkl"])
def test_evaluate_refuses_a_truncated_model_file(saved_run, tmp_path, broken):
    ok = run_cli("-m", "baselines.evaluate", "--quiet", "--set", "horizon=2", "--policy", str(saved_run))
    assert ok.returncode == 0, ok.stderr
    folder = _truncated_copy(saved_run, tmp_path / "run", broken)
    result = run_cli("-m", "baselines.evaluate", "--quiet", "--policy", str(folder))
    line = assert_one_line_error(result, str(folder / broken))
    assert ("cannot load the model" if broken.endswith(".zip") else "cannot load the normalization") in line


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--seed", "-1"], ["--seed", "got -1"]),
        (["--episodes", "0"], ["--episodes", "got 0"]),
        (["--policy", "random"], ["'random'"]),
    ],
)
def test_sweep_cli_errors_are_one_line(args, fragments):
    assert_one_line_error(run_cli("-m", "baselines.sweep", "--quiet", *args), *fragments)


# --------------------------------------------------------------------------- every scenario field, any type

#: Values of every type a user might pass by mistake (and some right ones).
ANY_VALUE = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**6), max_value=10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.sampled_from(["paper", "ring", "supply", "inf", "speed", "v", "1e3", ""]),
    st.lists(st.floats(min_value=-1e3, max_value=1e3), max_size=4),
    st.lists(st.lists(st.integers(-2, 2), min_size=3, max_size=3), min_size=3, max_size=3),
    st.dictionaries(st.sampled_from(["speed", "loss", "x", "a", "mean", "bogus"]), st.floats(-5, 5), max_size=2),
    st.tuples(st.floats(-10, 10), st.text(max_size=3)),
    st.builds(object),
    st.builds(lambda v: np.float64(v), st.floats(-10, 10)),
    st.builds(lambda v: np.int64(v), st.integers(-5, 50)),
)

FIELDS = [f.name for f in dataclasses.fields(ScenarioConfig)]


@pytest.mark.parametrize("field", FIELDS)
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(value=ANY_VALUE)
def test_any_value_of_any_field_is_accepted_and_round_trips_or_refused_by_name(field, value):
    try:
        cfg = make_config("paper", **{field: value})
    except ConfigError as err:
        assert field in str(err), f"{field}={value!r} refused without naming the field: {err}"
        return
    description = json.loads(json.dumps(cfg.to_dict(), allow_nan=False))
    assert config_from_dict(description).to_dict() == description


def test_round_trip_of_every_preset_and_of_a_schedule():
    for name in marine_formation_env.SCENARIOS:
        cfg = make_config(name)
        assert config_from_dict(json.loads(json.dumps(cfg.to_dict()))).to_dict() == cfg.to_dict()
    cfg = make_config("paper", topology=None, topology_schedule=[(1.0, "chain"), (0.5, "paper")])
    again = config_from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert [d for d, _ in again.topology_schedule] == [1.0, 0.5]
    assert math.isinf(again.channel.range)


# --------------------------------------------------------------------------- unknown keywords


@pytest.mark.parametrize(
    "make",
    [
        lambda **kw: marine_formation_env.parallel_env("paper", **kw),
        lambda **kw: gymnasium.make(ENV_ID, **kw),
        lambda **kw: gymnasium.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", **kw),
        lambda **kw: make_config("acoustic", **kw),
    ],
    ids=["parallel_env", "gymnasium.make", "make_vec", "make_config"],
)
def test_unknown_keywords_raise_a_type_error_in_pythons_wording(make):
    """Wrappers that probe optional keywords (TorchRL's GymEnv passes ``frameskip=``) match Python's own
    ``TypeError`` message; it is also a ``ConfigError`` and still names the valid keys."""
    with pytest.raises(TypeError, match=r"got an unexpected keyword argument 'frameskip'.*valid keys: \[.*'horizon'"):
        make(frameskip=4)
    with pytest.raises(ConfigError, match=r"unexpected keyword argument 'colour' \(and \['frameskip'\]\)"):
        make(frameskip=4, colour="red")


def test_a_horizon_too_long_for_the_default_workspace_is_refused_by_name():
    # found by the property test above: u_max · horizon overflowed the default workspace's x extent to inf,
    # and the refusal named the workspace, which the user never gave
    with pytest.raises(ConfigError, match=r"horizon = 2\.5e\+307"):
        make_config("paper", horizon=2.5e307)
    with pytest.raises(ConfigError, match="horizon"):
        make_config("paper", path="circle", horizon=1e308)
    assert make_config("paper", horizon=2.5e307, workspace=(-1e3, 1e4, -500.0, 500.0)).horizon == 2.5e307
