"""A hyperparameter given to ``load()`` (rl-zoo: ``train -i model.zip -params``) is applied or refused, not dropped."""

from __future__ import annotations

import inspect
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.utils import ConstantSchedule

import sb3_es
from sb3_es import ARS, CMAES, PGPE, REINFORCE, OpenES, SimpleES
from sb3_es.common.base_class import ESBaseAlgorithm
from sb3_es.common.population_algorithm import PopulationAlgorithm


@dataclass
class Case:
    """
    One algorithm's load-time changes.

    :param kwargs: Constructor arguments of the saved model (Pendulum-v1, 2 env slots).
    :param applied: Values given to ``load()`` that the model must use (and its strategy, for those it keeps).
    :param steps: Env steps of one generation (update) under the ``applied`` values.
    :param refused: A value ``load()`` must refuse (it cannot change once training has started).
    """

    kwargs: dict[str, Any]
    applied: dict[str, Any]
    steps: int
    refused: dict[str, Any] = field(default_factory=dict)


CASES: dict[type[BaseAlgorithm], Case] = {
    ARS: Case(
        dict(n_delta=4, delta_std=0.1), dict(delta_std=0.05, n_delta=2, n_top=1), 2 * 2 * 200, dict(zero_policy=False)
    ),
    OpenES: Case(
        dict(population_size=8),
        dict(population_size=4, sigma=0.05, learning_rate=0.002),
        4 * 200,
        dict(optimizer="sgd"),
    ),
    CMAES: Case(
        dict(population_size=4, restarts="ipop"), dict(max_restarts=0, n_eval_episodes=2), 4 * 2 * 200, dict(sigma=0.5)
    ),
    PGPE: Case(
        dict(population_size=8),
        dict(population_size=4, stdev_learning_rate=0.05, max_speed=0.1, max_stdev=0.08, common_seeds=True),
        4 * 200,
        dict(stdev_init=0.5),
    ),
    SimpleES: Case(dict(population_size=8), dict(population_size=4, sigma=0.05), 4 * 200, dict(n_elite=2)),
    REINFORCE: Case(dict(n_episodes=4), dict(learning_rate=0.05, n_episodes=2), 2 * 200, dict(use_baseline=True)),
}


def check_applied(model: Any, applied: dict[str, Any]) -> None:
    """The model, and what it built from its hyperparameters (strategy, torch optimizer), use the applied values."""
    for key, value in applied.items():
        assert getattr(model, key) == value
        if isinstance(model, PopulationAlgorithm) and hasattr(model.strategy, key):
            assert getattr(model.strategy, key) == value, key
    if isinstance(model, REINFORCE) and "learning_rate" in applied:
        assert model.policy.optimizer.param_groups[0]["lr"] == applied["learning_rate"]


def saved(cls: type[BaseAlgorithm], folder: Path) -> Path:
    """A model of ``cls`` trained for one generation on Pendulum-v1 and saved."""
    env = make_vec_env("Pendulum-v1", n_envs=2, seed=0)
    model = cls("MlpPolicy", env, seed=0, **CASES[cls].kwargs)
    model.learn(1)
    path = folder / f"{cls.__name__}.zip"
    model.save(path)
    env.close()
    return path


def test_every_algorithm_has_a_case() -> None:
    algorithms = {getattr(sb3_es, name) for name in sb3_es.__all__}
    assert {cls for cls in algorithms if isinstance(cls, type) and issubclass(cls, ESBaseAlgorithm)} == set(CASES)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_values_given_to_load_are_applied(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    case = CASES[cls]
    path = saved(cls, tmp_path)
    env = make_vec_env("Pendulum-v1", n_envs=2, seed=1)
    model = cls.load(path, env=env, **case.applied)
    start = model.num_timesteps
    model.learn(1, reset_num_timesteps=False)
    assert model.num_timesteps - start == case.steps  # the generation ran with the new values
    check_applied(model, case.applied)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_values_given_in_custom_objects_are_applied(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    # SB3's load() rebuilds the learning-rate schedule from a replaced learning_rate: a replaced hyperparameter drives
    # training, as one given as a keyword does, and the model does not show one value while its strategy uses another
    case = CASES[cls]
    model = cls.load(
        saved(cls, tmp_path), env=make_vec_env("Pendulum-v1", n_envs=2, seed=1), custom_objects=case.applied
    )
    start = model.num_timesteps
    model.learn(1, reset_num_timesteps=False)
    assert model.num_timesteps - start == case.steps
    check_applied(model, case.applied)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_rl_zoos_enjoy_objects_are_accepted(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    # rl-zoo's enjoy loads every model with these; a learning rate of 0 (refused by the constructors) stops the updates
    objects = {"learning_rate": 0.0, "lr_schedule": lambda _: 0.0, "clip_range": lambda _: 0.0}
    model = cls.load(saved(cls, tmp_path), env=make_vec_env("Pendulum-v1", n_envs=2, seed=1), custom_objects=objects)
    assert model.learning_rate == 0.0
    if "learning_rate" in inspect.signature(cls).parameters:
        before = model.policy.parameters_to_vector()
        model.learn(1, reset_num_timesteps=False)
        check_applied(model, {"learning_rate": 0.0})
        np.testing.assert_array_equal(model.policy.parameters_to_vector(), before)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_hyperparameters_left_out_of_a_save_take_their_defaults(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    # As in SB3, one left out by save(exclude=...) is the constructor's default after load(); the state built with the
    # saved value (the strategy) takes it too: the model ran with the saved value while it showed the default
    case = CASES[cls]
    short = dict(max_episode_steps=20)
    env = make_vec_env("Pendulum-v1", n_envs=2, seed=0, env_kwargs=short)
    model = cls("MlpPolicy", env, seed=0, **case.kwargs)
    model.learn(1)
    names = sorted(case.applied)
    model.save(tmp_path / "full.zip")
    model.save(tmp_path / "part.zip", exclude=names)
    defaults = {name: getattr(cls("MlpPolicy", env), name) for name in names}
    assert defaults != {name: getattr(model, name) for name in names} or cls is CMAES  # CMAES's case: its defaults
    runs, parameters = [], []
    for path, kwargs in ((tmp_path / "part.zip", {}), (tmp_path / "full.zip", defaults)):
        loaded = cls.load(path, env=make_vec_env("Pendulum-v1", n_envs=2, seed=1, env_kwargs=short), **kwargs)
        assert {name: getattr(loaded, name) for name in names} == defaults
        loaded.learn(1, reset_num_timesteps=False)
        strategy = getattr(loaded, "strategy", None)
        runs.append((loaded.num_timesteps, [getattr(strategy, name, None) for name in names]))
        parameters.append(loaded.policy.parameters_to_vector())
    assert runs[0] == runs[1]
    np.testing.assert_array_equal(*parameters)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_values_that_cannot_change_are_refused(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    path = saved(cls, tmp_path)
    ((key, value),) = CASES[cls].refused.items()
    with pytest.raises(ValueError, match=rf"{cls.__name__}.load\({key}=.*cannot change {key} once it has trained"):
        cls.load(path, **{key: value})
    # The saved value (given to the constructor, or its default) itself is fine, and kept.
    saved_value = CASES[cls].kwargs.get(key, inspect.signature(cls).parameters[key].default)
    assert saved_value != value
    model = cls.load(path, **{key: saved_value})
    assert type(model) is cls and getattr(model, key) == saved_value
    # The same through custom_objects, which SB3 would set on the model beside a strategy built with the saved value
    with pytest.raises(ValueError, match=rf"{cls.__name__}.load\({key}=.*cannot change {key} once it has trained"):
        cls.load(path, custom_objects={key: value})
    assert getattr(cls.load(path, custom_objects={key: saved_value}), key) == saved_value


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_bad_values_are_refused_as_by_the_constructor(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    path = saved(cls, tmp_path)
    bad = dict(max_episode_steps=0, **({"gamma": 1.5} if cls is REINFORCE else {"n_eval_episodes": 0}))
    for key, value in bad.items():
        with pytest.raises(ValueError, match=rf"^{key}={value}: ") as from_load:
            cls.load(path, **{key: value})
        with pytest.raises(ValueError) as from_constructor:
            cls("MlpPolicy", "Pendulum-v1", **{key: value})
        assert str(from_load.value) == str(from_constructor.value)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_unknown_names_are_refused(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    path = saved(cls, tmp_path)
    with pytest.raises(ValueError, match=rf"{cls.__name__}.load\(\) got learning_rat, which .* does not have"):
        cls.load(path, learning_rat=0.1)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_learning_rate_is_refused_where_the_algorithm_has_none(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    # SB3 saves learning_rate for every algorithm: CMA-ES, PGPE and SimpleES would keep it and never use it.
    path = saved(cls, tmp_path)
    if "learning_rate" in inspect.signature(cls).parameters:
        assert cls.load(path, learning_rate=0.5).learning_rate == 0.5
    else:
        with pytest.raises(ValueError, match=rf"{cls.__name__}.load\(\) got learning_rate, which .* does not have"):
            cls.load(path, learning_rate=0.5)


@pytest.mark.parametrize(
    "cls", [cls for cls in CASES if issubclass(cls, PopulationAlgorithm)], ids=lambda c: c.__name__
)
def test_an_unknown_evaluator_is_refused_by_load(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"evaluator='proceses': use 'local', 'processes', 'ray'"):
        cls.load(saved(cls, tmp_path), evaluator="proceses")


def test_ars_that_used_every_direction_keeps_using_every_direction(tmp_path: Path) -> None:
    ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0).save(tmp_path / "all.zip")  # n_top=None: every direction
    for n_delta in (4, 1):
        loaded = ARS.load(tmp_path / "all.zip", env=make_vec_env("Pendulum-v1", n_envs=2, seed=0), n_delta=n_delta)
        assert loaded.n_top == n_delta
        loaded.learn(1)
        assert loaded.strategy.n_top == n_delta
    ARS("LinearPolicy", "Pendulum-v1", n_delta=4, n_top=2, seed=0).save(tmp_path / "top.zip")
    assert ARS.load(tmp_path / "top.zip", n_delta=8).n_top == 2  # a chosen n_top stays


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_whole_number_floats_given_to_load_are_counts(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    # rl-zoo's -params or a YAML file may give a count as 2.0: the model and its strategy use the integer 2.
    case = CASES[cls]
    counts = {k: float(v) for k, v in case.applied.items() if type(v) is int}
    assert counts
    model = cls.load(saved(cls, tmp_path), env=make_vec_env("Pendulum-v1", n_envs=2, seed=1), **counts)
    start = model.num_timesteps
    model.learn(1, reset_num_timesteps=False)
    assert model.num_timesteps - start == case.steps
    for key, value in counts.items():
        assert type(getattr(model, key)) is int and getattr(model, key) == value
        if isinstance(model, PopulationAlgorithm) and hasattr(model.strategy, key):
            assert type(getattr(model.strategy, key)) is int


def test_values_checked_by_a_strategy_or_with_the_schedules_are_refused_on_load(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"max_restarts=-1: it must be at least 0"):
        CMAES.load(saved(CMAES, tmp_path), max_restarts=-1)
    with pytest.raises(ValueError, match=r"max_restarts=2.5: it must be a whole number"):
        CMAES.load(saved(CMAES, tmp_path), max_restarts=2.5)
    model = OpenES("MlpPolicy", "Pendulum-v1", population_size=4, sigma=lambda progress: 0.1 * progress)
    model.save(tmp_path / "openes.zip")
    with pytest.raises(ValueError, match=r"sigma_decay=0.5 decays a float sigma, but sigma is a schedule"):
        OpenES.load(tmp_path / "openes.zip", sigma_decay=0.5)


def test_load_takes_what_the_constructor_takes(tmp_path: Path) -> None:
    path = saved(ARS, tmp_path)
    model = ARS.load(path, reward_clip=np.array([-1.0, 1.0]), max_episode_steps=500.0, n_delta=2, n_top=None)
    assert model.reward_clip == (-1.0, 1.0) and type(model.max_episode_steps) is int and model.strategy.n_top == 2
    cmaes = saved(CMAES, tmp_path)
    for value in (-1, 2.5):
        with pytest.raises(ValueError) as from_load:
            CMAES.load(cmaes, max_restarts=value)
        with pytest.raises(ValueError) as from_constructor:
            CMAES("MlpPolicy", "Pendulum-v1", max_restarts=value)
        assert str(from_load.value) == str(from_constructor.value)


def test_saves_from_before_the_checks_still_load(tmp_path: Path) -> None:
    # Combinations the constructors now refuse, which older versions saved: a REINFORCE value_net_arch without a
    # baseline (it built none), an OpenES decay beside a schedule (the decay did nothing).
    reinforce = REINFORCE("MlpPolicy", "CartPole-v1", n_episodes=2)
    reinforce.policy_kwargs["value_net_arch"] = [8]
    reinforce.save(tmp_path / "reinforce.zip")
    assert REINFORCE.load(tmp_path / "reinforce.zip").policy.value_net_arch == [8]
    openes = OpenES("MlpPolicy", "Pendulum-v1", population_size=4, learning_rate=lambda progress: 0.01 * progress)
    openes.learning_rate_decay = 0.9
    openes.save(tmp_path / "openes.zip")
    OpenES.load(tmp_path / "openes.zip", env=make_vec_env("Pendulum-v1")).learn(1)
    assert OpenES.load(tmp_path / "openes.zip", learning_rate_decay=1.0).learning_rate_decay == 1.0


def test_the_saved_stats_window_size_is_no_change(tmp_path: Path) -> None:
    # SB3 saves it as _stats_window_size: load() compares with that, and names the saved value when it differs.
    path = saved(ARS, tmp_path)
    assert ARS.load(path, stats_window_size=100)._stats_window_size == 100
    with pytest.raises(ValueError, match=r"the saved model has stats_window_size=100, and ARS cannot change"):
        ARS.load(path, stats_window_size=10)


def test_ars_n_delta_below_a_chosen_n_top_is_refused(tmp_path: Path) -> None:
    ARS("LinearPolicy", "Pendulum-v1", n_delta=4, n_top=3, seed=0).save(tmp_path / "top.zip")
    with pytest.raises(ValueError, match=r"n_top=3 must be between 1 and n_delta=2"):
        ARS.load(tmp_path / "top.zip", n_delta=2)


def test_rl_zoos_constant_schedules_are_numbers(tmp_path: Path) -> None:
    # rl-zoo turns learning_rate: 0.05 and delta_std: 0.05 from a file or -params into ConstantSchedule objects
    model = ARS.load(saved(ARS, tmp_path), delta_std=ConstantSchedule(0.05), learning_rate=ConstantSchedule(0.01))
    assert model.delta_std == 0.05 and model.learning_rate == 0.01
    # a number, so that OpenES's learning_rate_decay applies to it
    openes = OpenES(
        "MlpPolicy", "Pendulum-v1", population_size=4, learning_rate=ConstantSchedule(0.1), learning_rate_decay=0.5
    )
    openes.learn(1600)
    assert openes.learning_rate == 0.1 and openes._n_updates == 2
    assert openes.strategy.learning_rate == pytest.approx(0.1 * 0.5**2)


#: ``(algorithm, its constructor arguments, a bad value for load())``: values checked by a strategy, by a flag
#: check or with the types, which load() must refuse with the constructor's own message.
REFUSED_LIKE_THE_CONSTRUCTOR = [
    (ARS, dict(n_delta=2), dict(seed=-1)),
    (ARS, dict(n_delta=2), dict(common_seeds="False")),
    (ARS, dict(n_delta=2), dict(learning_rate="0.05")),
    (OpenES, dict(population_size=4), dict(antithetic="False")),
    (OpenES, dict(population_size=4), dict(sigma_limit=-1)),
    (OpenES, dict(population_size=4), dict(weight_decay="0.01")),
    (OpenES, dict(population_size=4), dict(learning_rate_decay=0.9, learning_rate_limit=1.0)),
    (PGPE, dict(population_size=4), dict(stdev_max_change="0.1")),
    (CMAES, dict(population_size=4), dict(max_restarts=3)),  # no restarts: it would do nothing
    (REINFORCE, dict(n_episodes=2), dict(normalize_returns="False")),
]


@pytest.mark.parametrize(
    ("cls", "kwargs", "bad"),
    REFUSED_LIKE_THE_CONSTRUCTOR,
    ids=[f"{cls.__name__}-{'-'.join(bad)}" for cls, _, bad in REFUSED_LIKE_THE_CONSTRUCTOR],
)
def test_load_refuses_what_the_constructor_refuses(
    cls: type[BaseAlgorithm], kwargs: dict[str, Any], bad: dict[str, Any], tmp_path: Path
) -> None:
    cls("MlpPolicy", "Pendulum-v1", **kwargs).save(tmp_path / "model.zip")
    with pytest.raises((TypeError, ValueError)) as from_constructor:
        cls("MlpPolicy", "Pendulum-v1", **kwargs, **bad)
    with pytest.raises(from_constructor.type) as from_load:
        cls.load(tmp_path / "model.zip", **bad)
    assert str(from_load.value) == str(from_constructor.value)
    assert next(iter(bad)) in str(from_load.value)


def test_numpy_numbers_given_to_load_are_numbers(tmp_path: Path) -> None:
    path = saved(ARS, tmp_path)
    model = ARS.load(path, env=make_vec_env("Pendulum-v1", n_envs=2, seed=1), learning_rate=np.float32(0.05))
    model.learn(1, reset_num_timesteps=False)
    assert type(model.learning_rate) is float and model.strategy.learning_rate == pytest.approx(0.05)


def test_custom_objects_of_a_subclass_taking_kwargs_replace_as_in_sb3(tmp_path: Path) -> None:
    # its signature names no hyperparameter, so nothing in custom_objects can be checked as one: SB3's replacement
    class Wrapped(ARS):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)

    Wrapped("LinearPolicy", "Pendulum-v1", n_delta=2).save(tmp_path / "wrapped.zip")
    model = Wrapped.load(tmp_path / "wrapped.zip", custom_objects={"learning_rate": 2e-5, "dummy": 1.0})
    assert model.learning_rate == 2e-5


def test_openes_with_a_learning_rate_decay_takes_rl_zoos_enjoy_objects(tmp_path: Path) -> None:
    """A decayed learning rate's floor check does not turn learning_rate=0 (no update) away."""
    model = OpenES("LinearPolicy", "Pendulum-v1", population_size=4, learning_rate_decay=0.99, seed=0)
    model.learn(1)
    model.save(tmp_path / "model.zip")
    loaded = OpenES.load(tmp_path / "model.zip", custom_objects={"learning_rate": 0.0}, env=model.get_env())
    before = loaded.policy.parameters_to_vector()
    loaded.learn(1, reset_num_timesteps=False)
    np.testing.assert_array_equal(loaded.policy.parameters_to_vector(), before)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_custom_objects_replace_saved_values_that_cannot_be_read(
    cls: type[BaseAlgorithm], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # As SB3's custom_objects: saved objects whose module is gone are replaced, never read (they were read anyway,
    # and load() failed with a message advising custom_objects)
    module = f"gone_{cls.__name__.lower()}"
    (tmp_path / f"{module}.py").write_text(
        "import torch\n\nclass Act(torch.nn.Tanh):\n    pass\n\nclass Rate:\n    def __call__(self, progress):\n"
        "        return 0.01\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    gone = __import__(module)
    has_lr = "learning_rate" in inspect.signature(cls).parameters
    extra = {"learning_rate": gone.Rate()} if has_lr else {}
    env = make_vec_env("Pendulum-v1", n_envs=2, seed=0)
    model = cls("MlpPolicy", env, seed=0, policy_kwargs=dict(net_arch=[8], activation_fn=gone.Act), **extra)
    model.learn(1)
    model.save(tmp_path / "model.zip")
    monkeypatch.delitem(sys.modules, module)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p != str(tmp_path)])
    with pytest.raises(ValueError, match=f"module '{module}'"):
        cls.load(tmp_path / "model.zip")
    objects: dict[str, Any] = {"policy_kwargs": dict(net_arch=[8], activation_fn=th.nn.Tanh)}
    objects |= {"learning_rate": 0.0, "lr_schedule": lambda _: 0.0} if has_lr else {}  # as rl-zoo's enjoy gives them
    loaded = cls.load(tmp_path / "model.zip", env=make_vec_env("Pendulum-v1", n_envs=2, seed=1), custom_objects=objects)
    assert loaded.policy_kwargs["activation_fn"] is th.nn.Tanh
    np.testing.assert_array_equal(loaded.policy.parameters_to_vector(), model.policy.parameters_to_vector())
    loaded.learn(1, reset_num_timesteps=False)
    if has_lr:
        check_applied(loaded, {"learning_rate": 0.0})


@pytest.mark.parametrize("cls", list(CASES), ids=lambda cls: cls.__name__)
def test_a_save_without_any_one_hyperparameter_loads_and_trains(cls: type[BaseAlgorithm], tmp_path: Path) -> None:
    # Left out, each takes the constructor's default, which must suit the saved model: CMAES's max_restarts default
    # was refused without restarts, and ARS's n_top became 8 (the default n_delta's) beside n_delta=1
    env = make_vec_env("Pendulum-v1", n_envs=2, seed=0, env_kwargs=dict(max_episode_steps=20))
    size = {"n_delta": 1} if cls is ARS else {"n_episodes": 2} if cls is REINFORCE else {"population_size": 4}
    model = cls("MlpPolicy", env, seed=0, **size)
    model.learn(1)
    assert issubclass(cls, ESBaseAlgorithm)
    names = sorted(cls._applicable_on_load() & cls._parameters() - {"verbose"})  # verbose: SB3 reads it, as for PPO
    assert len(names) >= 5
    for name in [*names, "_env_rng"] if isinstance(model, PopulationAlgorithm) else names:
        model.save(tmp_path / "model.zip", exclude=[name])
        loaded = cls.load(tmp_path / "model.zip", env=env)
        loaded.learn(1, reset_num_timesteps=False)
        assert loaded.num_timesteps > model.num_timesteps, name
