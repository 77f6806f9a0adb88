"""Clear errors for bad hyperparameters, unsupported environments and save files (non-finite returns of every
algorithm: ``test_algorithms.py``)."""

from __future__ import annotations

import base64
import json
import re
import warnings
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from algorithms import ALGORITHMS, ALGOS, POPULATION_ALGORITHMS, Algo
from envs import MultiDiscreteActionEnv, SpaceEnv
from gymnasium import spaces
from gymnasium.wrappers import TimeLimit
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.common.vec_env import VecNormalize

import sb3_es
from sb3_es import ARS, CMAES, PGPE, REINFORCE, OpenES, SimpleES
from sb3_es.evaluation import VecEnvEvaluator
from sb3_es.evaluation.time_limit import env_time_limit


# ---------------------------------------------------------------------------- hyperparameters
def each(cls: type, name: str, values: list[Any], match: str | None = None, **kwargs: Any) -> list[Any]:
    """One entry per bad value of one hyperparameter (with ``kwargs``); the error must name it, or match ``match``."""
    return [
        pytest.param(
            cls,
            {**kwargs, name: value},
            match or rf"\b{name}=",
            id="-".join([cls.__name__, *(f"{k}={v}" for k, v in kwargs.items()), name, str(i)]),
        )
        for i, value in enumerate(values)
    ]


NAN, INF = float("nan"), float("inf")
#: Every algorithm class, and the population methods' (from ``ALGOS``: a new algorithm is covered).
CLASSES = [algo.cls for algo in ALGOS]
POPULATION_CLASSES = [algo.cls for algo in ALGOS if algo.population]
#: ``(algorithm, constructor arguments, what the error message must match)``: every algorithm's bad values.
BAD_HYPERPARAMETERS = [
    *each(ARS, "n_delta", [0, -1, 2.5, NAN, INF, "8"], r"n_delta=(0|-1|2.5|nan|inf|'8'): it must be"),
    *[
        pytest.param(ARS, dict(n_delta=n_delta, n_top=n_top), "n_top", id=f"ARS-n_top-{i}")
        for i, (n_delta, n_top) in enumerate([(2, 3), (4, 5), (4, 0), (4, -1), (4, 1.5), (4, NAN)])
    ],
    *each(ARS, "delta_std", [0.0, -0.05, NAN, INF, lambda progress: -progress]),
    *each(ARS, "learning_rate", [0.0, -0.02, NAN, INF, lambda progress: 0.0]),
    *[  # checked by the population methods' shared base
        param
        for cls in POPULATION_CLASSES
        for param in each(cls, "n_eval_episodes", [0, -2, 1.5, NAN, "2"], r"n_eval_episodes=(0|-2|1.5|nan|'2'): ")
    ],
    *[
        param
        for cls in CLASSES
        for param in each(cls, "max_episode_steps", [0, -5, 2.5, NAN, "100"], r"max_episode_steps=\S+: it must be")
    ],
    *each(OpenES, "population_size", [1, 0, -2], antithetic=True),
    *each(OpenES, "population_size", [1, 0, -2, 4.5], antithetic=False),
    *each(OpenES, "sigma", [0.0, -0.1, NAN, lambda progress: 0.0]),
    *each(OpenES, "sigma_decay", [0.0, -0.5, 1.01, 2.0]),
    *each(OpenES, "learning_rate_decay", [0.0, -0.5, 1.01, 2.0]),
    *each(OpenES, "sigma_limit", [-1, NAN], r"sigma_limit=(-1|nan): it must be a finite number >= 0"),
    *each(OpenES, "learning_rate_limit", [-1], r"learning_rate_limit=-1: it must be a finite number >= 0"),
    *each(OpenES, "momentum", [NAN], r"momentum=nan: the SGD and ClipUp momentum must be in \[0, 1\)"),
    *each(OpenES, "momentum", [NAN, 1.5], r"momentum=(nan|1.5)", optimizer="sgd"),
    *each(OpenES, "weight_decay", [NAN, -0.1]),
    *each(OpenES, "fitness_shaping", ["ranks"]),
    *each(OpenES, "optimizer", ["rmsprop"]),
    *each(CMAES, "population_size", [1, 0, -3, 5.5]),
    *each(CMAES, "sigma", [0.0, -0.1, NAN, INF]),
    *each(CMAES, "max_restarts", [-1, 1.5, NAN], r"max_restarts=(-1|1.5|nan): it must be (at least 0|a whole number)"),
    *each(CMAES, "max_restarts", [3], r"max_restarts=3 has no effect without restarts", restarts=None),
    *each(SimpleES, "noise_table_size", [1000.5, 0]),
    *each(CMAES, "diagonal", ["yes", 1, 0]),
    *each(CMAES, "restarts", ["lpop"]),
    *each(PGPE, "population_size", [3, 7, 0, 4.5, "4"]),
    *each(PGPE, "stdev_init", [0.0]),
    *each(PGPE, "stdev_max_change", [1.0, 0.0]),
    *each(PGPE, "stdev_learning_rate", [-0.1]),
    *each(PGPE, "max_speed", [0.0]),
    *each(PGPE, "momentum", [1.0]),
    *each(PGPE, "momentum", [5.0, NAN], optimizer="adam", center_learning_rate=0.01),
    *each(
        PGPE,
        "momentum",
        [1.5, -0.1],
        r"momentum=(1.5|-0.1): the SGD and ClipUp momentum",
        optimizer="sgd",
        center_learning_rate=0.1,
    ),
    *each(PGPE, "optimizer", ["adam"], "center_learning_rate"),
    *each(PGPE, "max_speed", [0.2], optimizer="adam", center_learning_rate=0.01),
    *each(PGPE, "optimizer", ["rmsprop"], center_learning_rate=0.01),
    *each(PGPE, "fitness_shaping", ["rank"]),
    *each(SimpleES, "n_elite", [0, 17, 1.5]),
    *each(SimpleES, "population_size", [1, 4.5]),
    *each(SimpleES, "sigma", [0.0]),
    *each(SimpleES, "weights", ["fitness"]),
    *each(REINFORCE, "n_episodes", [0, -3, 1.5, NAN], r"n_episodes=(0|-3|1.5|nan): it must be"),
    *each(REINFORCE, "learning_rate", [0.0, -1e-3, lambda _: -1.0], r"learning_rate=(0.0|-0.001|-1.0)"),
    *each(REINFORCE, "gamma", [1.5, -0.1], r"gamma=(1.5|-0.1).*\[0, 1\]"),
    *each(REINFORCE, "max_grad_norm", [0.0], "max_grad_norm=0.0"),
    *each(
        REINFORCE,
        "policy_kwargs",
        [dict(n_bins=1), dict(n_bins=2.5), dict(n_bins=NAN)],
        r"n_bins=(1|2.5|nan): it must be",
    ),
    *each(REINFORCE, "policy_kwargs", [dict(use_baseline=True)], "use_baseline"),
    *each(
        REINFORCE,
        "policy_kwargs",
        [dict(net_arch=dict(pi=[8], vf=[8]))],
        r"\(vf\) of REINFORCE is its baseline.*use_baseline",
    ),
    *each(
        REINFORCE,
        "policy_kwargs",
        [dict(net_arch=dict(pi=[8], vf=[8]), value_net_arch=[4])],
        "both give the baseline's layers",
        use_baseline=True,
    ),
    *each(REINFORCE, "policy_kwargs", [dict(net_arch=dict(pi=[8], qf=[8]))], r"unknown entry \['qf'\]"),
    *each(REINFORCE, "policy_kwargs", [dict(joint=True, max_joint_actions=1000.7)], "max_joint_actions=1000.7"),
    *each(REINFORCE, "policy_kwargs", [dict(value_net_arch=[7])], r"value_net_arch=\[7\] gives .* use_baseline=True"),
    *[param for cls in CLASSES for param in each(cls, "stats_window_size", [0, -1])],
    *each(OpenES, "learning_rate_decay", [0.9], r"learning_rate_decay=0.9 would never apply", learning_rate=0.0005),
    *each(OpenES, "sigma_decay", [0.99], r"sigma_decay=0.99 would never apply", sigma=0.005),
    *[
        param
        for cls in POPULATION_CLASSES
        for param in each(
            cls, "policy_kwargs", [dict(layer_norm=True), dict(activation_fn=th.nn.Tanh)], "LinearPolicy has no hidden"
        )
    ],
    *each(
        REINFORCE,
        "policy_kwargs",
        [dict(value_net_arch=[8, 0])],
        r"value_net_arch=\[8, 0\]: give a list of positive",
        use_baseline=True,
    ),
]


#: ``(algorithm, hyperparameter)``: number-valued hyperparameters, which a string must not reach as a number.
NUMBERS = [
    *[(ARS, name) for name in ("delta_std", "learning_rate")],
    *[(OpenES, name) for name in ("sigma", "sigma_decay", "learning_rate", "momentum")],
    (CMAES, "sigma"),
    *[(PGPE, name) for name in ("stdev_init", "max_speed", "max_stdev", "stdev_learning_rate")],
    (SimpleES, "sigma"),
    *[(REINFORCE, name) for name in ("learning_rate", "gamma", "ent_coef", "max_grad_norm")],
]


@pytest.mark.parametrize(("cls", "name"), NUMBERS, ids=[f"{cls.__name__}-{name}" for cls, name in NUMBERS])
def test_a_number_given_as_a_string_is_named(cls: type, name: str) -> None:
    # YAML (1.1, as PyYAML reads it) takes 1e-2, without a dot, for a string
    policy = "MlpPolicy" if cls is REINFORCE else "LinearPolicy"
    with pytest.raises(TypeError, match=rf"{name}='1e-2': it must be a number \(a string; .* write 1.0e-2\)"):
        cls(policy, "Pendulum-v1", **{name: "1e-2"})


def test_the_yaml_hint_is_given_for_a_string_that_reads_as_a_number_only() -> None:
    for value in ("auto", "exp_0.02"):  # SAC's ent_coef, a schedule rl-zoo does not have: 1.0e-2 is no fix
        with pytest.raises(TypeError) as info:
            ARS("LinearPolicy", "Pendulum-v1", learning_rate=value)
        assert str(info.value) == f"learning_rate={value!r}: it must be a number (a string)."


#: Every algorithm's number-valued hyperparameters, with values its constructor takes together (with
#: :data:`OPTIONS`, the other arguments those values need); the population methods' shared ones are in
#: :data:`SHARED_FLOATS`.
FLOATS: dict[type, dict[str, float]] = {
    ARS: dict(learning_rate=0.05, delta_std=0.04),
    OpenES: dict(
        sigma=0.2,
        learning_rate=0.05,
        sigma_decay=0.99,
        sigma_limit=0.02,
        learning_rate_decay=0.99,
        learning_rate_limit=0.002,
        momentum=0.5,
        max_speed=0.3,
        weight_decay=0.01,
    ),
    CMAES: dict(sigma=0.3),
    PGPE: dict(
        stdev_init=0.2,
        max_speed=0.3,
        center_learning_rate=0.1,
        stdev_learning_rate=0.2,
        stdev_max_change=0.3,
        max_stdev=0.5,
        momentum=0.8,
    ),
    SimpleES: dict(sigma=0.2),
    REINFORCE: dict(learning_rate=0.05, gamma=0.9, ent_coef=0.01, max_grad_norm=0.5),
}
SHARED_FLOATS = dict(alive_bonus_offset=-1.0, terminal_reward=0.5)
OPTIONS: dict[type, dict[str, Any]] = {OpenES: dict(optimizer="clipup")}


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_numpy_numbers_are_numbers(algo: Algo, tmp_path: Path) -> None:
    """
    np.float32 is no Python float, which SB3's schedules take: the model converts it, as np.int64 counts, and keeps
    and saves Python numbers.
    """
    floats = {**FLOATS[algo.cls], **(SHARED_FLOATS if algo.population else {})}
    counts = {**algo.size(4), **(dict(n_eval_episodes=1) if algo.population else {})}
    numpy_values = {key: np.float32(value) for key, value in floats.items()}
    numpy_values |= {key: np.int64(value) for key, value in counts.items()}
    model = algo.make("Pendulum-v1", 4, **numpy_values, **OPTIONS.get(algo.cls, {}))
    model.learn(1)
    model.save(tmp_path / "model.zip")
    for when, m in (("constructed", model), ("loaded", algo.cls.load(tmp_path / "model.zip"))):
        for key, value in floats.items():
            assert type(getattr(m, key)) is float and getattr(m, key) == pytest.approx(value), f"{when} {key}"
            if algo.population and hasattr(m.strategy, key):
                assert type(getattr(m.strategy, key)) is float, f"{when} strategy.{key}"
        for key, value in counts.items():
            assert type(getattr(m, key)) is int and getattr(m, key) == value, f"{when} {key}"


def test_optimizer_names_are_checked_first() -> None:
    # before the settings that depend on the optimizer, whose messages would otherwise read as nonsense
    with pytest.raises(ValueError, match=r"^optimizer='ClipUp': choose one of 'adam', 'sgd', 'clipup' \(lower case\)"):
        OpenES("LinearPolicy", "Pendulum-v1", optimizer="ClipUp", max_speed=0.2)
    with pytest.raises(ValueError, match=r"^optimizer='Adam': choose one of"):
        PGPE("LinearPolicy", "Pendulum-v1", optimizer="Adam")


@pytest.mark.parametrize(
    ("cls", "kwargs"),
    [(OpenES, dict(momentum=0.5)), (PGPE, dict(optimizer="adam", center_learning_rate=0.01, momentum=0.5))],
)
def test_momentum_with_adam_is_refused(cls: type, kwargs: dict[str, Any]) -> None:
    # as max_speed is: a setting the chosen optimizer does not use
    with pytest.raises(ValueError, match=r"^momentum=0.5 is an SGD and ClipUp setting; it has no effect with"):
        cls("LinearPolicy", "Pendulum-v1", **kwargs)


def test_cma_options_must_be_a_dict() -> None:
    with pytest.raises(TypeError, match=r"cma_options='dict\(tolfun=1e-3\)': it must be a dict of pycma options"):
        CMAES("LinearPolicy", "Pendulum-v1", cma_options="dict(tolfun=1e-3)")


def test_a_noise_table_smaller_than_a_perturbation_is_refused_at_construction() -> None:
    with pytest.raises(ValueError, match=r"^noise_table_size=3 is smaller than one perturbation \(4 parameters\)"):
        ARS("LinearPolicy", "Pendulum-v1", noise_table_size=3, policy_kwargs=dict(with_bias=True))


@pytest.mark.parametrize(
    ("cls", "kwargs"),
    [
        (CMAES, dict(sigma=lambda _: 0.1)),
        (PGPE, dict(stdev_init=lambda _: 0.1)),
        (PGPE, dict(max_speed=lambda _: 0.1)),
        (PGPE, dict(optimizer="adam", center_learning_rate=lambda _: 0.01)),
    ],
)
def test_a_schedule_where_none_is_taken_is_named(cls: type, kwargs: dict[str, Any]) -> None:
    name = next(key for key, value in kwargs.items() if callable(value))
    with pytest.raises(TypeError, match=rf"{name}=<function .*: it must be a number \({name} takes no schedule\)"):
        cls("LinearPolicy", "Pendulum-v1", **kwargs)


@pytest.mark.parametrize(
    ("cls", "kwargs"),
    [
        *[(cls, dict(common_seeds="no")) for cls in POPULATION_CLASSES],
        *[(cls, dict(zero_policy="False")) for cls in POPULATION_CLASSES],
        (ARS, dict(policy_kwargs=dict(normalize_observations="False"))),
        (REINFORCE, dict(normalize_returns="false")),
        (REINFORCE, dict(use_baseline="false")),
        (OpenES, dict(antithetic="False")),
        (OpenES, dict(forget_best="False")),
        *[(ARS, dict(policy_kwargs={name: "False"})) for name in ("with_bias", "squash_output")],
        (REINFORCE, dict(policy_kwargs=dict(joint="false"))),
    ],
)
def test_a_flag_given_as_a_string_is_named(cls: type, kwargs: dict[str, Any]) -> None:
    # a non-empty string is true: "False" would switch the option on
    policy = "MlpPolicy" if cls is REINFORCE else "LinearPolicy"
    with pytest.raises(TypeError, match=r"(common_seeds='no'|\w+='(F|f)alse'): it must be True or False"):
        cls(policy, "Pendulum-v1", **kwargs)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_max_episode_steps_above_the_envs_own_limit(algo: Algo, tmp_path: Path) -> None:
    # Pendulum-v1's TimeLimit ends every episode at 200 steps, whatever the cap: refused as soon as both are known
    match = r"max_episode_steps=300 is above the env's own time limit \(200 steps\)"
    with pytest.raises(ValueError, match=match):
        algo.make("Pendulum-v1", 2, max_episode_steps=300)
    longer = dict(wrapper_class=TimeLimit, wrapper_kwargs=dict(max_episode_steps=400))
    model = algo.make(make_vec_env("Pendulum-v1", n_envs=2, **longer), 2, max_episode_steps=300)
    with pytest.raises(ValueError, match=match):
        model.set_env(make_vec_env("Pendulum-v1", n_envs=2))
    assert env_time_limit(model.get_env()) == 400  # the model keeps its env
    algo.make("Pendulum-v1", 2).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=match):
        algo.cls.load(tmp_path / "model.zip", env=make_vec_env("Pendulum-v1", n_envs=2), max_episode_steps=300)
    model.save(tmp_path / "capped.zip")  # the saved cap, with an env given to load(): refused at load, not at learn()
    with pytest.raises(ValueError, match=match):
        algo.cls.load(tmp_path / "capped.zip", env=make_vec_env("Pendulum-v1", n_envs=2))


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_a_cap_that_a_vec_env_wrapper_hides_is_refused_at_set_env_and_load(algo: Algo, tmp_path: Path) -> None:
    # VecNormalize would not see a slot reset: the fix is a time limit of the cap itself inside each env
    match = r"through VecNormalize .*env_kwargs=dict\(max_episode_steps=50\)\)"
    model = algo.make(make_vec_env("Pendulum-v1", n_envs=2), 2, max_episode_steps=50)
    with pytest.raises(ValueError, match=match):
        model.set_env(VecNormalize(make_vec_env("Pendulum-v1", n_envs=2)))
    model.save(tmp_path / "capped.zip")
    with pytest.raises(ValueError, match=match):
        algo.cls.load(tmp_path / "capped.zip", env=VecNormalize(make_vec_env("Pendulum-v1", n_envs=2)))


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_observations_normalized_twice_are_warned_about(algo: Algo) -> None:
    """A VecNormalize (rl-zoo's ``normalize: true``) and the policy's running normalization: a warning names both."""
    match = r"VecNormalize\(norm_obs=True\) and the policy normalizes observations itself .* normalized twice"
    with pytest.warns(UserWarning, match=match):
        model = algo.make(VecNormalize(make_vec_env("Pendulum-v1", n_envs=2)), 2)
    with pytest.warns(UserWarning, match=match):
        model.set_env(VecNormalize(make_vec_env("Pendulum-v1", n_envs=2)))
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*normalized twice")
        algo.make(VecNormalize(make_vec_env("Pendulum-v1", n_envs=2), norm_obs=False), 2)
        algo.make(
            VecNormalize(make_vec_env("Pendulum-v1", n_envs=2)), 2, policy_kwargs=dict(normalize_observations=False)
        )


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_whole_number_floats_are_counts(algo: Algo) -> None:
    # A YAML file or rl-zoo's -params can give a count as 4.0: it is used as the integer 4.
    counts = {key: float(value) for key, value in algo.size(4).items()}
    if algo.population:
        counts["n_eval_episodes"] = 1.0
    model = algo.make("Pendulum-v1", 4, **counts)
    model.learn(1)
    for key, value in counts.items():
        assert type(getattr(model, key)) is int and getattr(model, key) == value, key
        if algo.population and hasattr(model.strategy, key):
            assert type(getattr(model.strategy, key)) is int, key
    assert model.num_timesteps == 4 * 200  # 4 candidates (episodes) of 200 steps


@pytest.mark.parametrize(("cls", "kwargs", "match"), BAD_HYPERPARAMETERS)
def test_bad_hyperparameters_are_named(cls: type, kwargs: dict[str, Any], match: str) -> None:
    policy = "MlpPolicy" if cls is REINFORCE else "LinearPolicy"
    with pytest.raises(ValueError, match=match):
        cls(policy, "Pendulum-v1", **kwargs)


def test_delta_std_schedule_reaching_zero_during_training() -> None:
    """A schedule that becomes non-positive mid-run stops with a clear error before that generation."""
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, delta_std=lambda progress: progress - 0.5, seed=0)
    with pytest.raises(ValueError, match="delta_std"):
        model.learn(4 * 400)
    # Generations ran while the schedule was positive (progress 1.0 and 0.75), then it stopped at 0.5.
    assert model._n_updates == 2
    assert model.num_timesteps == 2 * 400


# ---------------------------------------------------------------------------- environments and policies
@pytest.mark.parametrize("algo", ALGORITHMS)
def test_unknown_env_id(algo: Algo) -> None:
    with pytest.raises(gym.error.Error, match="NoSuchEnvAtAll"):
        algo.make("NoSuchEnvAtAll-v0", 2)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_unbounded_box_action_env(algo: Algo) -> None:
    # SB3's own check is a bare AssertionError: each algorithm checks first, naming the fix
    env = MultiDiscreteActionEnv()
    env.action_space = gym.spaces.Box(-np.inf, np.inf, shape=(2,), dtype=np.float32)  # type: ignore[assignment]
    with pytest.raises(
        ValueError, match=r"^Unsupported action space Box\(-inf, inf.*: (the )?Box bounds must be finite"
    ):
        algo.make(env, 2)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_multi_discrete_action_env(algo: Algo) -> None:
    with pytest.raises(ValueError, match="MultiDiscrete") as info:
        algo.make(MultiDiscreteActionEnv(), 2)
    assert "action space" in str(info.value)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_unknown_policy_alias(algo: Algo) -> None:
    names = ", ".join(sorted(algo.cls.policy_aliases))
    with pytest.raises(ValueError, match=rf"^Policy 'CnnPolicy' unknown: {algo.name}'s policies are {names}, or give"):
        algo.make("Pendulum-v1", 2, policy="CnnPolicy")


def test_reinforces_linear_policy_is_an_mlp_without_hidden_layers() -> None:
    # the other algorithms have a LinearPolicy: the likely mistake gets the equivalent
    with pytest.raises(ValueError, match=r"A linear policy is MlpPolicy with policy_kwargs=dict\(net_arch=\[\]\)"):
        REINFORCE("LinearPolicy", "CartPole-v1")


class NotFlatPolicy(BasePolicy):
    """A valid SB3 policy without flat parameters."""

    def _predict(self, observation, deterministic: bool = False):  # pragma: no cover - never called
        raise NotImplementedError


@pytest.mark.parametrize(
    ("cls", "policy", "expected"),
    [
        (ARS, NotFlatPolicy, "FlatPolicy"),
        (ARS, ActorCriticPolicy, "FlatPolicy"),  # it would fail building, asking for lr_schedule
        (REINFORCE, sb3_es.MlpPolicy, "DiscretizedPolicy"),  # it would fail building, on use_baseline
    ],
)
def test_a_policy_class_the_algorithm_cannot_train_is_named(cls: type, policy: type, expected: str) -> None:
    with pytest.raises(TypeError, match=rf"^{cls.__name__} needs a {expected} subclass, got {policy.__name__}: pass"):
        cls(policy, "Pendulum-v1")


@pytest.mark.parametrize("policy_kwargs", [dict(n_bins=7), dict(joint=True)])
def test_reinforce_refuses_discretizing_discrete_actions(policy_kwargs: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match=r"they discretize a Box action space, but Discrete\(2\) is used as it is"):
        REINFORCE("MlpPolicy", "CartPole-v1", policy_kwargs=policy_kwargs)


def test_reinforce_refuses_a_tuple_observation_space_at_construction() -> None:
    with pytest.raises(ValueError, match=r"Unsupported observation space Tuple\(.*FlattenObservation"):
        REINFORCE("MlpPolicy", gym.make("Blackjack-v1"))


@pytest.mark.parametrize("algo", ALGORITHMS)
@pytest.mark.parametrize("in_dict", [False, True], ids=["alone", "in-a-dict"])
def test_a_multidiscrete_observation_with_a_2d_nvec_is_refused_by_name(algo: Algo, in_dict: bool) -> None:
    # it failed with NumPy's "only 0-dimensional arrays can be converted to Python scalars"
    space = spaces.MultiDiscrete(np.array([[2, 3], [2, 2]]))
    env = SpaceEnv(spaces.Dict({"grid": space}) if in_dict else space, spaces.Box(-1, 1, (2,)))
    with pytest.raises(ValueError, match=r"a MultiDiscrete with a 2-D nvec \(2, 2\); wrap the env with .*Flatten"):
        algo.make(env, 2)


# ---------------------------------------------------------------------------- schedules during training
@pytest.mark.parametrize(
    ("algorithm", "kwargs", "updates_before"),
    [
        # A generation (ARS, OpenES) or an update (REINFORCE, one episode) is 400 or 200 Pendulum steps.
        (ARS, dict(policy="LinearPolicy", n_delta=1), 2),
        (OpenES, dict(policy="LinearPolicy", population_size=2), 2),
        (REINFORCE, dict(policy="MlpPolicy", n_episodes=1), 1),
    ],
)
def test_learning_rate_schedule_going_negative_during_training(algorithm, kwargs, updates_before: int) -> None:
    """
    ``progress - 0.6`` starts positive. ARS and OpenES check it before each generation (progress 1, 0.75,
    0.5: the third is refused), REINFORCE after collecting each update's episodes (progress 0.75, 0.5: the
    second is refused).
    """
    steps = 400 if algorithm is not REINFORCE else 200
    model = algorithm(env="Pendulum-v1", learning_rate=lambda progress: progress - 0.6, seed=0, **kwargs)
    with pytest.raises(ValueError, match=r"learning_rate schedule gave -0.1 at progress_remaining=0.5: it must stay"):
        model.learn(4 * steps)
    assert model._n_updates == updates_before
    for param in model.policy.parameters():
        assert th.all(th.isfinite(param))


@pytest.mark.parametrize(
    ("algorithm", "kwargs"),
    [
        (ARS, dict(policy="LinearPolicy", n_delta=1)),
        (OpenES, dict(policy="LinearPolicy", population_size=2)),
        (REINFORCE, dict(policy="MlpPolicy", n_episodes=1)),
    ],
)
@pytest.mark.parametrize("bad", [None, "0.01"], ids=["None", "a-string"])
def test_learning_rate_schedule_giving_a_non_number_during_training(algorithm, kwargs, bad: Any) -> None:
    """It gave ``float()``'s TypeError without the schedule's name, or (a string) was taken as a number."""
    steps = 400 if algorithm is not REINFORCE else 200
    model = algorithm(
        env="Pendulum-v1", learning_rate=lambda progress: 0.01 if progress > 0.6 else bad, seed=0, **kwargs
    )
    match = rf"learning_rate schedule gave {bad!r} at progress_remaining=0.5: it must return a number"
    with pytest.raises(TypeError, match=match):
        model.learn(4 * steps)


def test_learning_rate_schedule_ending_at_zero_is_accepted() -> None:
    model = REINFORCE("MlpPolicy", "Pendulum-v1", n_episodes=1, learning_rate=lambda progress: 0.01 * progress, seed=0)
    model.learn(600)  # the last update sees progress 0 (it ends at 600 steps): learning rate 0
    assert model._n_updates == 3


# ---------------------------------------------------------------------------- algorithm hyperparameters
def test_cmaes_population_too_small_for_two_point_adaptation() -> None:
    """From 300 parameters pycma's TPA takes 2 candidates per generation and mirroring one more."""
    match = r"population_size=2 is too small for CMA-ES on 4481 parameters.*TPA.*population_size >= 3"
    with pytest.raises(ValueError, match=match):
        CMAES("MlpPolicy", "Pendulum-v1", population_size=2)
    # The smallest population that pycma runs, and population 2 on a small policy, both train.
    for policy, size in (("MlpPolicy", 3), ("LinearPolicy", 2)):
        model = CMAES(policy, "Pendulum-v1", population_size=size, seed=0)
        model.learn(size * 200)
        assert model._n_updates == 1


def test_cmaes_full_covariance_too_large_for_memory() -> None:
    """Refused before pycma allocates anything, with the memory needed and the fix."""
    n = 3 * 1024 + 1024 + 1024 * 1024 + 1024 + 1024 + 1  # Pendulum, net_arch=[1024, 1024]
    gib = 5 * 8 * n**2 / 2**30
    with pytest.raises(MemoryError, match=rf"on {n} parameters needs about {gib:,.1f} GiB.*diagonal=True"):
        CMAES("MlpPolicy", "Pendulum-v1", diagonal=False, policy_kwargs=dict(net_arch=[1024, 1024]))


@pytest.mark.parametrize("algo", ALGORITHMS)
@pytest.mark.parametrize("seed", [-1, 2**32, 1.5])
def test_seed_out_of_range(algo: Algo, seed: float) -> None:
    with pytest.raises(ValueError, match=re.escape(f"seed={seed!r}: it must be an integer in [0, 2**32 - 1]")):
        algo.make("Pendulum-v1", 2, seed=seed)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_numpy_integer_seed(algo: Algo) -> None:
    # Python's random refuses a NumPy integer deep inside set_random_seed; the model takes it as the same int
    model = algo.make("Pendulum-v1", 2, seed=np.int64(3))
    assert type(model.seed) is int and model.seed == 3
    model.set_random_seed(np.int64(4))


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_policy_kwargs_that_is_not_a_dict(algo: Algo) -> None:
    with pytest.raises(TypeError, match=r"policy_kwargs='net_arch=\[8\]': it must be a dict of the policy's keyword"):
        algo.make("Pendulum-v1", 2, policy_kwargs="net_arch=[8]")


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_predict_refuses_a_nan_observation(algo: Algo) -> None:
    model = algo.make("Pendulum-v1", 2)
    model.predict(np.zeros(3, np.float32))
    with pytest.raises(ValueError, match=r"predict\(\): the observation holds NaN or infinite values"):
        model.predict(np.array([0.0, np.nan, 1.0], np.float32))


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_population_policy_given_actor_critic_net_arch(algo: Algo) -> None:
    with pytest.raises(ValueError, match=r"net_arch=\{'pi': \[32\], 'vf': \[32\]\}: .*no value network.*\[64, 64\]"):
        algo.make("Pendulum-v1", 2, policy="MlpPolicy", policy_kwargs=dict(net_arch=dict(pi=[32], vf=[32])))


# ---------------------------------------------------------------------------- save files
def test_set_parameters_refuses_another_algorithms_zip(tmp_path: Path) -> None:
    ARS("LinearPolicy", "Pendulum-v1", seed=0).save(tmp_path / "ars.zip")
    model = OpenES("LinearPolicy", "Pendulum-v1", seed=0)
    with pytest.raises(ValueError, match=r"with OpenES\.set_parameters\(\): it was saved by sb3-es ARS"):
        model.set_parameters(str(tmp_path / "ars.zip"))
    # The way the message gives to use its weights anyway works.
    weights = ARS.load(tmp_path / "ars.zip").policy.state_dict()
    model.set_parameters({"policy": weights})
    np.testing.assert_array_equal(model.strategy.center, model.policy.parameters_to_vector())


def garble_action_space(path: Path) -> Path:
    """Copy of a save whose ``action_space`` names a class that no longer exists (as after a library update)."""
    garbled = path.with_name("garbled.zip")
    with zipfile.ZipFile(path) as source, zipfile.ZipFile(garbled, "w") as target:
        for item in source.infolist():
            content = source.read(item)
            if item.filename == "data":
                data = json.loads(content)
                data["action_space"][":serialized:"] = base64.b64encode(b"cgymnasium.spaces\nRemovedBox\n.").decode()
                content = json.dumps(data).encode()
            target.writestr(item, content)
    return garbled


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_load_with_custom_objects_does_not_warn(tmp_path: Path, algo: Algo) -> None:
    original = algo.make("Pendulum-v1", 2)
    original.save(tmp_path / "model.zip")
    garbled = garble_action_space(tmp_path / "model.zip")
    with (
        pytest.warns(UserWarning, match="Could not deserialize object action_space"),
        pytest.raises(KeyError, match="observation_space and action_space were not given"),
    ):
        algo.cls.load(garbled)  # SB3 needs the action space
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="Could not deserialize")
        model = algo.cls.load(garbled, custom_objects={"action_space": original.action_space})
    obs = np.zeros((4, 3), dtype=np.float32)
    np.testing.assert_array_equal(
        model.predict(obs, deterministic=True)[0], original.predict(obs, deterministic=True)[0]
    )


def test_an_evaluator_on_another_env_is_named() -> None:
    evaluator = VecEnvEvaluator(make_vec_env("Acrobot-v1"))  # 6 observations; the model's CartPole-v1 has 4
    model = ARS("LinearPolicy", "CartPole-v1", n_delta=2, evaluator=evaluator)
    with pytest.raises(ValueError, match=r"The evaluator's env has observation_space Box.*same env \(and wrappers\)"):
        model.learn(1)


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_unknown_policy_kwargs_are_named_with_the_policys_arguments(algo: Algo) -> None:
    """A key copied from another algorithm's rl-zoo entry (PPO's log_std_init) is named, with what the policy takes."""
    with pytest.raises(TypeError, match=r"policy_kwargs \['log_std_init'\]: .* Its arguments are .*net_arch"):
        algo.make("Pendulum-v1", 4, policy="MlpPolicy", policy_kwargs=dict(net_arch=[8], log_std_init=-1.0))


@pytest.mark.parametrize("algo", ALGORITHMS)
@pytest.mark.parametrize("value", ["tanh", th.nn.Tanh()], ids=["name", "instance"])
def test_an_activation_fn_that_is_not_a_class_is_named(algo: Algo, value: Any) -> None:
    with pytest.raises(TypeError, match=r"activation_fn=.*: pass a subclass of torch\.nn\..*Module, e\.g\. "):
        algo.make("Pendulum-v1", 4, policy="MlpPolicy", policy_kwargs=dict(activation_fn=value))


def test_reinforce_policy_flags_and_optimizer_class_are_checked() -> None:
    with pytest.raises(TypeError, match=r"optimizer_class='adam': pass a subclass of torch\.optim"):
        REINFORCE("MlpPolicy", "Pendulum-v1", policy_kwargs=dict(optimizer_class="adam"))
    with pytest.raises(TypeError, match="ortho_init=.no.: it must be True or False"):
        REINFORCE("MlpPolicy", "Pendulum-v1", policy_kwargs=dict(ortho_init="no"))


@pytest.mark.parametrize("cls", [ARS, OpenES])
def test_learning_rate_none_is_named(cls: type) -> None:
    """None is for the algorithms without a learning rate of their own (CMA-ES, SimpleES)."""
    with pytest.raises(TypeError, match="learning_rate=None: it must be a number"):
        cls("LinearPolicy", "Pendulum-v1", learning_rate=None)


@pytest.mark.parametrize("value", [np.bool_(True), np.bool_(False)])
def test_cmaes_diagonal_takes_a_numpy_bool(value: np.bool_) -> None:
    """As every other flag: kept as a Python bool (saved and compared as one)."""
    model = CMAES("LinearPolicy", "Pendulum-v1", diagonal=value)
    assert model.diagonal is bool(value)
