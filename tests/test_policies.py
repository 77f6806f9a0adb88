"""Behaviour of the flat-parameter policies: predict, batched population forward pass, normalization, spaces."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from torch import nn

from sb3_es.common.policies import OBS_NORM_EPS, FlatPolicy, LinearPolicy, MlpPolicy

OBS_BOX = spaces.Box(-5.0, 5.0, shape=(3,), dtype=np.float32)
ACT_BOX = spaces.Box(np.array([-2.0, 0.0], dtype=np.float32), np.array([2.0, 0.5], dtype=np.float32))
ACT_DISCRETE = spaces.Discrete(4)


def random_params(policy: FlatPolicy, n: int, scale: float = 1.0, seed: int = 0) -> np.ndarray:
    return scale * np.random.default_rng(seed).standard_normal((n, policy.num_params))


def random_obs(space: spaces.Box, n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-3.0, 3.0, size=(n, *space.shape)).astype(np.float32)


# ---------------------------------------------------------------------------- predict
@pytest.mark.parametrize("policy_class", [MlpPolicy, LinearPolicy])
def test_predict_box_shapes_and_bounds(policy_class: type[FlatPolicy]) -> None:
    policy = policy_class(OBS_BOX, ACT_BOX)
    # Large weights push the raw outputs far outside the bounds (tanh saturates, or clipping kicks in).
    policy.load_from_vector(random_params(policy, 1, scale=10.0)[0])
    obs = random_obs(OBS_BOX, 16)

    single, state = policy.predict(obs[0])
    assert state is None
    assert single.shape == ACT_BOX.shape
    batched, _ = policy.predict(obs)
    assert batched.shape == (16, *ACT_BOX.shape)
    assert np.all(batched >= ACT_BOX.low) and np.all(batched <= ACT_BOX.high)
    np.testing.assert_allclose(batched[0], single, rtol=1e-6, atol=1e-6)
    # Some actions should sit on the bounds with such weights: the outputs really were squashed or clipped.
    assert np.any(np.isclose(batched, ACT_BOX.low, atol=1e-3) | np.isclose(batched, ACT_BOX.high, atol=1e-3))
    # Not all identical: the policy depends on the observation.
    assert np.unique(batched[:, 0]).size > 1


@pytest.mark.parametrize("policy_class", [MlpPolicy, LinearPolicy])
def test_predict_discrete_returns_ints(policy_class: type[FlatPolicy]) -> None:
    policy = policy_class(OBS_BOX, ACT_DISCRETE)
    policy.load_from_vector(random_params(policy, 1)[0])
    obs = random_obs(OBS_BOX, 32)

    single, _ = policy.predict(obs[0])
    assert np.shape(single) == ()
    assert np.issubdtype(np.asarray(single).dtype, np.integer)
    assert ACT_DISCRETE.contains(int(single))
    batched, _ = policy.predict(obs)
    assert batched.shape == (32,)
    assert np.issubdtype(batched.dtype, np.integer)
    assert np.all((batched >= 0) & (batched < ACT_DISCRETE.n))
    assert batched[0] == single
    assert np.unique(batched).size > 1


def test_predict_is_deterministic_flag_independent() -> None:
    policy = MlpPolicy(OBS_BOX, ACT_BOX)
    policy.load_from_vector(random_params(policy, 1)[0])
    obs = random_obs(OBS_BOX, 4)
    np.testing.assert_array_equal(
        policy.predict(obs, deterministic=True)[0], policy.predict(obs, deterministic=False)[0]
    )


# ---------------------------------------------------------------------------- population forward pass
POPULATION_CASES = {
    "mlp_tanh_squash": (MlpPolicy, ACT_BOX, dict(net_arch=[8, 5], activation_fn=nn.Tanh)),
    "mlp_layer_norm": (MlpPolicy, ACT_BOX, dict(net_arch=[8, 6], layer_norm=True)),
    "mlp_no_squash_clip": (MlpPolicy, ACT_BOX, dict(net_arch=[7], squash_output=False)),
    "linear_clip": (LinearPolicy, ACT_BOX, dict()),
    "linear_bias_clip": (LinearPolicy, ACT_BOX, dict(with_bias=True)),
    "mlp_softmax": (MlpPolicy, ACT_BOX, dict(net_arch=[8], activation_fn=nn.Softmax)),
    "mlp_discrete": (MlpPolicy, ACT_DISCRETE, dict(net_arch=[6, 6])),
    "linear_discrete": (LinearPolicy, ACT_DISCRETE, dict()),
}


@pytest.mark.parametrize("case", list(POPULATION_CASES))
@pytest.mark.parametrize("with_obs_stats", [False, True])
def test_population_actions_match_predict(case: str, with_obs_stats: bool) -> None:
    policy_class, action_space, kwargs = POPULATION_CASES[case]
    policy = policy_class(OBS_BOX, action_space, **kwargs)
    if with_obs_stats:
        policy.update_obs_rms(np.array([0.5, -1.0, 2.0]), np.array([4.0, 0.25, 1.0]), 100)
    n = 7
    params = random_params(policy, n, scale=0.5)
    obs = random_obs(OBS_BOX, n)

    actions = policy.population_actions(np.asarray(params, dtype=np.float32), policy.flatten_obs(obs))
    if isinstance(action_space, spaces.Discrete):
        assert actions.shape == (n,)
    else:
        assert actions.shape == (n, *action_space.shape)
    # Each row must be what a policy holding that row's parameters predicts for that row's observation.
    expected = []
    for k in range(n):
        policy.load_from_vector(params[k])
        expected.append(policy.predict(obs[k])[0])
    expected = np.array(expected)
    if isinstance(action_space, spaces.Discrete):
        np.testing.assert_array_equal(actions, expected)
        assert np.unique(actions).size > 1
    else:
        np.testing.assert_allclose(actions, expected, rtol=1e-5, atol=1e-5)
        assert np.all(actions >= action_space.low) and np.all(actions <= action_space.high)
        assert np.unique(actions[:, 0]).size > 2  # not all saturated


@pytest.mark.parametrize("net_arch", [[], dict(pi=[])])
def test_layer_norm_without_hidden_layers_is_refused(net_arch: list | dict) -> None:
    """An MLP without hidden layers has nothing for ``layer_norm`` to normalize: it was accepted and did nothing."""
    with pytest.raises(ValueError, match=r"layer_norm=True with net_arch=.*Give hidden layers"):
        MlpPolicy(OBS_BOX, ACT_BOX, net_arch=net_arch, layer_norm=True)
    assert MlpPolicy(OBS_BOX, ACT_BOX, net_arch=net_arch).net_arch == []


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        (dict(layer_norm=True), "layer_norm=True"),  # it also named an activation_fn=ReLU never given
        (dict(activation_fn=nn.Tanh), "activation_fn=Tanh"),
        (dict(layer_norm=True, activation_fn=nn.Tanh), "layer_norm=True and activation_fn=Tanh"),
    ],
)
def test_linear_policy_names_the_options_given_that_need_hidden_layers(kwargs: dict, named: str) -> None:
    with pytest.raises(ValueError, match=rf"^LinearPolicy has no hidden layers, so {named} would do nothing"):
        LinearPolicy(OBS_BOX, ACT_BOX, **kwargs)


@pytest.mark.parametrize(
    "kwargs", [dict(layer_norm=True), dict(activation_fn=nn.Softmax)], ids=["layer_norm", "softmax"]
)
def test_population_actions_row_independent(kwargs: dict) -> None:
    """Changing one row's parameters must not change any other row's action (an activation that is not element-wise
    acts within a row, as in the torch policy)."""
    policy = MlpPolicy(OBS_BOX, ACT_BOX, net_arch=[8], **kwargs)
    params = random_params(policy, 4)
    obs = policy.flatten_obs(random_obs(OBS_BOX, 4))
    before = policy.population_actions(np.asarray(params, dtype=np.float32), obs)
    params[2] += 1.0
    after = policy.population_actions(np.asarray(params, dtype=np.float32), obs)
    np.testing.assert_array_equal(np.delete(before, 2, axis=0), np.delete(after, 2, axis=0))
    assert not np.allclose(before[2], after[2])


# ---------------------------------------------------------------------------- flat parameters
@pytest.mark.parametrize(
    ("policy_class", "kwargs", "expected_num"),
    [
        (MlpPolicy, dict(net_arch=[4, 5]), 3 * 4 + 4 + 4 * 5 + 5 + 5 * 2 + 2),
        (MlpPolicy, dict(net_arch=[4], layer_norm=True), 3 * 4 + 4 + 4 + 4 + 4 * 2 + 2),
        (MlpPolicy, dict(net_arch=[4], with_bias=False), 3 * 4 + 4 * 2),
        (LinearPolicy, dict(), 3 * 2),
        (LinearPolicy, dict(with_bias=True), 3 * 2 + 2),
    ],
)
def test_vector_round_trip(policy_class: type[FlatPolicy], kwargs: dict, expected_num: int) -> None:
    policy = policy_class(OBS_BOX, ACT_BOX, **kwargs)
    assert policy.num_params == expected_num
    vector = random_params(policy, 1)[0]
    policy.load_from_vector(vector)
    out = policy.parameters_to_vector()
    assert out.dtype == np.float64 and out.shape == (expected_num,)
    np.testing.assert_array_equal(out, vector.astype(np.float32).astype(np.float64))
    # The vector really is written into the layers (first weight matrix, row major, first).
    first = next(m for m in policy.action_net if isinstance(m, nn.Linear))
    w = first.weight.detach().numpy()
    np.testing.assert_array_equal(w, vector[: w.size].astype(np.float32).reshape(w.shape))
    # Observation statistics are buffers, not parameters.
    policy.update_obs_rms(np.ones(3), np.ones(3), 10)
    np.testing.assert_array_equal(policy.parameters_to_vector(), out)


def test_load_from_vector_wrong_shape() -> None:
    policy = LinearPolicy(OBS_BOX, ACT_BOX)
    with pytest.raises(ValueError, match="shape"):
        policy.load_from_vector(np.zeros(policy.num_params + 1))


# ---------------------------------------------------------------------------- observation normalization
def make_linear_identity_like(normalize: bool) -> tuple[LinearPolicy, np.ndarray]:
    """A linear policy with wide action bounds (no clipping) and known weights."""
    wide = spaces.Box(-1e6, 1e6, shape=(2,), dtype=np.float32)
    policy = LinearPolicy(OBS_BOX, wide, normalize_observations=normalize)
    weights = np.array([[1.0, -2.0, 0.5], [0.25, 3.0, -1.0]])
    policy.load_from_vector(weights.ravel())
    return policy, weights


def test_update_obs_rms_then_predict_normalizes() -> None:
    policy, weights = make_linear_identity_like(normalize=True)
    data = np.random.default_rng(3).normal([1.0, -2.0, 4.0], [0.5, 2.0, 3.0], size=(500, 3))
    batch_mean, batch_var, batch_count = data.mean(0), data.var(0), data.shape[0]
    policy.update_obs_rms(batch_mean, batch_var, batch_count)

    # Manual merge with the prior (mean 0, var 1, count 1e-4), the parallel-variance formula.
    prior_count = 1e-4
    total = prior_count + batch_count
    mean = batch_mean * batch_count / total
    m2 = 1.0 * prior_count + batch_var * batch_count + np.square(batch_mean) * prior_count * batch_count / total
    var = m2 / total
    np.testing.assert_allclose(policy.obs_mean.numpy(), mean, rtol=1e-12)
    np.testing.assert_allclose(policy.obs_var.numpy(), var, rtol=1e-12)
    assert policy.obs_count.item() == pytest.approx(total)

    obs = random_obs(OBS_BOX, 5)
    expected = ((obs - mean) / np.sqrt(var + OBS_NORM_EPS)) @ weights.T
    np.testing.assert_allclose(policy.predict(obs)[0], expected, rtol=1e-5, atol=1e-5)
    # The batched population path uses the same statistics.
    params = np.asarray(np.tile(weights.ravel(), (5, 1)), dtype=np.float32)
    np.testing.assert_allclose(
        policy.population_actions(params, policy.flatten_obs(obs)), expected, rtol=1e-5, atol=1e-5
    )


def test_update_obs_rms_merges_batches() -> None:
    policy, _ = make_linear_identity_like(normalize=True)
    rng = np.random.default_rng(4)
    a, b = rng.normal(2.0, 3.0, size=(300, 3)), rng.normal(-1.0, 0.5, size=(700, 3))
    policy.update_obs_rms(a.mean(0), a.var(0), len(a))
    policy.update_obs_rms(b.mean(0), b.var(0), len(b))
    both = np.concatenate([a, b])
    np.testing.assert_allclose(policy.obs_mean.numpy(), both.mean(0), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(policy.obs_var.numpy(), both.var(0), rtol=1e-5, atol=1e-5)
    # An empty batch changes nothing.
    before = policy.obs_mean.numpy().copy()
    policy.update_obs_rms(np.full(3, 100.0), np.ones(3), 0)
    np.testing.assert_array_equal(policy.obs_mean.numpy(), before)


def test_normalize_observations_false_ignores_stats() -> None:
    policy, weights = make_linear_identity_like(normalize=False)
    policy.update_obs_rms(np.array([10.0, -5.0, 3.0]), np.array([100.0, 0.01, 4.0]), 1000)
    obs = random_obs(OBS_BOX, 5)
    expected = obs.astype(np.float64) @ weights.T
    np.testing.assert_allclose(policy.predict(obs)[0], expected, rtol=1e-5, atol=1e-5)
    params = np.asarray(np.tile(weights.ravel(), (5, 1)), dtype=np.float32)
    np.testing.assert_allclose(
        policy.population_actions(params, policy.flatten_obs(obs)), expected, rtol=1e-5, atol=1e-5
    )


@pytest.mark.parametrize(
    "space", [spaces.Discrete(3, start=1), spaces.MultiDiscrete([3, 2], start=[1, -1])], ids=["Discrete", "Multi"]
)
def test_discrete_observations_with_a_start_are_one_hot_from_their_start(space: spaces.Space) -> None:
    # SB3's preprocess_obs counts from 0: its one-hot of Discrete(3, start=1)'s largest value, 3, fails
    policy = LinearPolicy(space, ACT_DISCRETE, normalize_observations=False)
    space.seed(0)
    samples = np.stack([space.sample() for _ in range(20)])
    expected = np.stack([spaces.flatten(space, sample) for sample in samples])  # gymnasium's one-hot, from start
    np.testing.assert_array_equal(policy.flatten_obs(samples), expected)
    assert policy.predict(samples[0])[0] in range(4)


# ---------------------------------------------------------------------------- Dict observations
DICT_SPACE = spaces.Dict(
    {
        "position": spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32),
        "image_like": spaces.Box(-1.0, 1.0, shape=(3, 2), dtype=np.float32),
        "height": spaces.Box(-np.inf, np.inf, shape=(), dtype=np.float64),
    }
)


def test_dict_observations_are_flattened() -> None:
    wide = spaces.Box(-1e6, 1e6, shape=(2,), dtype=np.float32)
    policy = LinearPolicy(DICT_SPACE, wide, normalize_observations=False)
    assert policy.obs_dim == 2 + 6 + 1
    weights = np.random.default_rng(5).standard_normal((2, 9))
    policy.load_from_vector(weights.ravel())

    DICT_SPACE.seed(0)
    samples = [DICT_SPACE.sample() for _ in range(4)]
    flat = np.stack([spaces.flatten(DICT_SPACE, s) for s in samples]).astype(np.float64)
    expected = flat @ weights.T

    single, _ = policy.predict(samples[0])
    np.testing.assert_allclose(single, expected[0], rtol=1e-5, atol=1e-5)
    batched_obs = {key: np.stack([s[key] for s in samples]) for key in DICT_SPACE.spaces}
    batched, _ = policy.predict(batched_obs)
    np.testing.assert_allclose(batched, expected, rtol=1e-5, atol=1e-5)

    flat_t = policy.flatten_obs(batched_obs)
    assert tuple(flat_t.shape) == (4, 9)
    np.testing.assert_allclose(flat_t, flat, rtol=1e-6)
    params = np.asarray(np.tile(weights.ravel(), (4, 1)), dtype=np.float32)
    np.testing.assert_allclose(policy.population_actions(params, flat_t), expected, rtol=1e-5, atol=1e-5)


def test_dict_observations_mlp_population_matches_predict() -> None:
    policy = MlpPolicy(DICT_SPACE, ACT_BOX, net_arch=[5])
    params = random_params(policy, 3)
    DICT_SPACE.seed(1)
    samples = [DICT_SPACE.sample() for _ in range(3)]
    batched_obs = {key: np.stack([s[key] for s in samples]) for key in DICT_SPACE.spaces}
    actions = policy.population_actions(np.asarray(params, dtype=np.float32), policy.flatten_obs(batched_obs))
    for k in range(3):
        policy.load_from_vector(params[k])
        np.testing.assert_allclose(actions[k], policy.predict(samples[k])[0], rtol=1e-5, atol=1e-5)


# ---------------------------------------------------------------------------- unsupported spaces
@pytest.mark.parametrize(
    ("observation_space", "name"),
    [
        (spaces.Tuple((spaces.Box(-1, 1, (2,)), spaces.Discrete(3))), "Tuple"),
        (spaces.Text(5), "Text"),
        (spaces.Dict({"a": spaces.Box(-1, 1, (2,)), "b": spaces.Tuple((spaces.Discrete(3),))}), "Tuple"),
    ],
)
@pytest.mark.parametrize("policy_class", [MlpPolicy, LinearPolicy])
def test_unsupported_observation_space(
    observation_space: spaces.Space, name: str, policy_class: type[FlatPolicy]
) -> None:
    with pytest.raises(ValueError, match="observation space") as info:
        policy_class(observation_space, ACT_BOX)
    message = str(info.value)
    assert name in message
    assert "FlattenObservation" in message  # suggests a fix


@pytest.mark.parametrize(
    ("action_space", "name"),
    [(spaces.MultiDiscrete([3, 2]), "MultiDiscrete"), (spaces.MultiBinary(3), "MultiBinary")],
)
@pytest.mark.parametrize("policy_class", [MlpPolicy, LinearPolicy])
def test_unsupported_action_space(action_space: spaces.Space, name: str, policy_class: type[FlatPolicy]) -> None:
    with pytest.raises(ValueError, match="action space") as info:
        policy_class(OBS_BOX, action_space)
    message = str(info.value)
    assert name in message
    assert "wrap" in message.lower()  # suggests a fix


def test_unbounded_box_action_space_rejected() -> None:
    with pytest.raises(ValueError, match="finite"):
        MlpPolicy(OBS_BOX, spaces.Box(-np.inf, np.inf, shape=(2,), dtype=np.float32))


def test_linear_policy_rejects_net_arch() -> None:
    with pytest.raises(ValueError, match="net_arch"):
        LinearPolicy(OBS_BOX, ACT_BOX, net_arch=[16])
    # An empty net_arch is a linear policy and is accepted.
    assert LinearPolicy(OBS_BOX, ACT_BOX, net_arch=[]).num_params == 3 * 2
    # So is SB3's actor-critic form of it; a value network is refused as for MlpPolicy.
    assert LinearPolicy(OBS_BOX, ACT_BOX, net_arch=dict(pi=[])).num_params == 3 * 2
    with pytest.raises(ValueError, match="no value network"):
        LinearPolicy(OBS_BOX, ACT_BOX, net_arch=dict(pi=[], vf=[8]))


@pytest.mark.parametrize("activation_fn", ["tanh", nn.Tanh()])
def test_activation_fn_must_be_a_module_class(activation_fn: Any) -> None:
    with pytest.raises(
        TypeError,
        match=r"activation_fn=.*: pass a subclass of torch\.nn\..*Module, e\.g\. activation_fn=torch\.nn\.Tanh",
    ):
        MlpPolicy(OBS_BOX, ACT_BOX, activation_fn=activation_fn)


def test_mlp_rejects_non_positive_layer_sizes() -> None:
    with pytest.raises(ValueError, match="net_arch"):
        MlpPolicy(OBS_BOX, ACT_BOX, net_arch=[8, 0])
