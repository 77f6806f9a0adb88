"""How to build a VecEnv's envs again in a worker: the recipe read from the Gymnasium specs of its envs.

``evaluator="processes"`` or ``"ray"`` needs each worker to build envs like the model's. Given an env id that is
the id; given a VecEnv (as rl-zoo's ``ExperimentManager`` or ``make_vec_env`` builds it), the recipe is read from
``env.spec`` of its envs: ``gym.make`` of the spec with the wrappers applied before SB3's ``Monitor``, then the
wrappers applied after it (``make_vec_env``'s ``wrapper_class``), each rebuilt from its recorded constructor
arguments. What cannot be rebuilt (an env without a spec, a wrapper that does not record its arguments, a VecEnv
wrapper such as ``VecNormalize``, envs that differ) raises an error naming it, rather than being dropped.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec, WrapperSpec, load_env_creator
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper, VecTransposeImage

from sb3_es.evaluation.worker import WorkerEnvArgs, with_sb3_wrappers

_MONITOR = "stable_baselines3.common.monitor:Monitor"


def _apply_wrappers(env: gym.Env, wrappers: tuple[WrapperSpec, ...]) -> gym.Env:
    for wrapper in wrappers:
        wrapper_cls: Any = load_env_creator(wrapper.entry_point)
        env = wrapper_cls(env, **(wrapper.kwargs or {}))
    return env


def _same_spec(spec: EnvSpec, other: EnvSpec) -> bool:
    """
    Whether two envs' specs describe the same env.

    ``gym.make`` copies the spec into each env, and a copied ``functools.partial`` entry point (shimmy registers
    ``dm_control/...`` that way) never equals the original: entry points given as partials are compared by their
    function and arguments instead.
    """
    entry, other_entry = spec.entry_point, other.entry_point
    if isinstance(entry, functools.partial) and isinstance(other_entry, functools.partial):
        if (entry.func, entry.args, entry.keywords) != (other_entry.func, other_entry.args, other_entry.keywords):
            return False
        other = dataclasses.replace(other, entry_point=entry)
    return spec == other


def _spec_difference(spec: EnvSpec, other: EnvSpec) -> str:
    """Where two envs' specs differ, in words: the wrapper argument, or else the first differing field."""
    first, second = spec.additional_wrappers, other.additional_wrappers
    if len(first) == len(second):
        for mine, theirs in zip(first, second, strict=True):
            if mine == theirs:
                continue
            if mine.name == theirs.name and mine.kwargs is not None and theirs.kwargs is not None:
                keys = [
                    key for key in {**mine.kwargs, **theirs.kwargs} if mine.kwargs.get(key) != theirs.kwargs.get(key)
                ]
                hint = (
                    " (a function or lambda made anew for each env is a new object each time: define it once and "
                    "pass that one to every env)"
                    if any(callable(mine.kwargs.get(key)) for key in keys)
                    else ""
                )
                return f"in the {mine.name} wrapper's {', '.join(keys)}{hint}"
            return f"in their wrappers, {mine.name} and {theirs.name}"
    for field in dataclasses.fields(EnvSpec):
        if getattr(spec, field.name) != getattr(other, field.name):
            return f"in their specs' {field.name}"
    return "in their specs"


def env_recipe(env: VecEnv, evaluator: str) -> tuple[functools.partial[gym.Env], WorkerEnvArgs]:
    """
    The env factory and ``make_vec_env`` arguments with which a worker builds envs like those of ``env``.

    :param env: The model's VecEnv.
    :param evaluator: The evaluator's name, for the error messages.
    :return: A picklable factory (``gym.make`` of the spec, with the wrappers inside ``Monitor``) and the worker
        env arguments (``wrapper_class`` for the wrappers outside ``Monitor``, ``monitor_kwargs`` for its
        ``info_keywords``).
    """
    specs: list[EnvSpec | None] = env.get_attr("spec")
    spec = specs[0]
    registered = f"the env id instead (env={spec.id!r})" if spec is not None else "a registered env id instead"
    fix = (
        f"give {registered}, or pass evaluator=ProcessEvaluator(env_factory) / "
        f"RayEvaluator(env_factory) built with a factory for your envs (evaluator={evaluator!r} builds every "
        f"worker's envs itself)"
    )
    if isinstance(env, VecTransposeImage) and isinstance(with_sb3_wrappers(env.venv), VecTransposeImage):
        env = env.venv  # added by SB3 to the model's env: the workers add it to theirs
    if isinstance(env, VecEnvWrapper):
        raise ValueError(
            f"evaluator={evaluator!r}: the env is wrapped in {type(env).__name__}, which the workers cannot apply "
            f"to their own envs: remove the VecEnv wrapper (the policies normalize observations themselves; with "
            f"rl-zoo, remove normalize and frame_stack from the entry or pass -params normalize:False), or {fix}."
        )
    if spec is None:
        raise ValueError(f"evaluator={evaluator!r}: the env was not built by gym.make (it has no spec): {fix}.")
    for other in specs[1:]:
        if other is None or not _same_spec(spec, other):
            why = "one has no spec" if other is None else _spec_difference(spec, other)
            raise ValueError(f"evaluator={evaluator!r}: the VecEnv's envs differ, {why}: {fix}.")
    wrappers = tuple(spec.additional_wrappers)
    names = [wrapper.entry_point for wrapper in wrappers]
    cut = names.index(_MONITOR) if _MONITOR in names else len(wrappers)
    inner, outer = wrappers[:cut], wrappers[cut + 1 :]
    opaque = [wrapper.name for wrapper in inner + outer if wrapper.kwargs is None]
    if opaque:
        raise ValueError(
            f"evaluator={evaluator!r}: the env's wrapper(s) {', '.join(opaque)} do not record their constructor "
            f"arguments (gymnasium.utils.RecordConstructorArgs), so a worker cannot rebuild them: {fix}."
        )
    factory = functools.partial(gym.make, dataclasses.replace(spec, additional_wrappers=inner))
    args: WorkerEnvArgs = {}
    if cut < len(wrappers):  # the workers' Monitor reports the same info keywords (rl-zoo's "is_success")
        info_keywords = tuple(env.get_attr("info_keywords", indices=[0])[0])
        if info_keywords:
            args["monitor_kwargs"] = {"info_keywords": info_keywords}
    if outer:
        wrap: Any = functools.partial(_apply_wrappers, wrappers=outer)
        args["wrapper_class"] = wrap
    return factory, args
