"""Episode length caps: read a VecEnv's time limit, and end an episode that reaches a cap as ``TimeLimit`` would."""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np
from stable_baselines3.common.env_util import unwrap_wrapper
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from sb3_es.evaluation.slot_reset import can_reset_slots, reset_slot


def env_time_limit(env: VecEnv) -> int | None:
    """
    The episode length limit of a VecEnv's envs (gymnasium's ``TimeLimit`` wrapper).

    :param env: The VecEnv.
    :return: The largest ``max_episode_steps`` over the env slots, or ``None`` if a slot has no ``TimeLimit``.
    """
    # Asked by attribute (the one TimeLimit keeps its limit in), not by class: rl_zoo3 replaces gymnasium's TimeLimit
    # with a subclass in the processes that import it, so the envs of a SubprocVecEnv's workers, which do not, are
    # not instances of the class seen here, and the class may not even pickle.
    try:
        if not env.has_attr("_max_episode_steps"):
            return None
        return max(int(limit) for limit in env.get_attr("_max_episode_steps"))
    except (AttributeError, NotImplementedError, TypeError, ValueError):  # a VecEnv that cannot tell
        return None


def end_capped_episodes(
    env: VecEnv,
    max_episode_steps: int | None,
    lengths: np.ndarray,
    new_obs: np.ndarray | dict[str, np.ndarray],
    dones: np.ndarray,
    infos: list[dict[str, Any]],
) -> None:
    """
    End the episodes that reached ``max_episode_steps`` steps without ending, as a ``TimeLimit`` inside the VecEnv
    would have: the slot's ``done`` is set, its info gets ``TimeLimit.truncated`` and ``terminal_observation``, and
    the slot is reset (``env_method("reset")``) with its first observation written into ``new_obs``. The slot's
    ``Monitor`` (in a ``DummyVecEnv``) ends the episode as if the time limit were inside it: it writes its row and
    the info gets its ``"episode"``. Arguments are changed in place, right after ``env.step()`` and before they are
    used.

    A single slot can be reset only on a VecEnv that is not a ``VecEnvWrapper`` (a ``VecNormalize`` or
    ``VecFrameStack`` would not see the reset): there, reaching the cap raises an error that says to give each env
    a ``TimeLimit``.

    :param env: The VecEnv just stepped.
    :param max_episode_steps: The cap (``None``: none).
    :param lengths: Length of each slot's current episode, this step included.
    :param new_obs: Observations returned by the step.
    :param dones: Dones returned by the step.
    :param infos: Infos returned by the step.
    """
    if max_episode_steps is None:
        return
    slots = np.flatnonzero((lengths >= max_episode_steps) & ~np.asarray(dones, dtype=bool))
    if len(slots) == 0:
        return
    if not can_reset_slots(env):
        raise RuntimeError(
            f"An episode reached max_episode_steps={max_episode_steps} steps without ending, and the env's episodes "
            f"cannot be cut one slot at a time through {type(env).__name__} (the VecEnv wrapper would not see the "
            f"reset). Give each env that time limit before wrapping the VecEnv, inside its Monitor, e.g. "
            f"make_vec_env(env_id, env_kwargs=dict(max_episode_steps={max_episode_steps}))."
        )
    for slot in slots.tolist():
        infos[slot]["TimeLimit.truncated"] = True
        monitor = _slot_monitor(env, slot)
        if monitor is not None and not monitor.needs_reset:
            infos[slot]["episode"] = _end_monitor_episode(monitor, infos[slot])
        elif monitor is None and not isinstance(env.unwrapped, DummyVecEnv) and env.env_is_wrapped(Monitor, [slot])[0]:
            warnings.warn(
                f"An episode cut at max_episode_steps={max_episode_steps} by the evaluation cannot be ended in its "
                f"Monitor, which runs in another process ({type(env.unwrapped).__name__}): the Monitor files and "
                "get_episode_rewards() miss the cut episodes (rollout/ep_rew_mean has them). Give each env the time "
                f"limit inside its Monitor (make_vec_env(env_id, env_kwargs=dict(max_episode_steps="
                f"{max_episode_steps}))), or use evaluator='processes', whose workers run whole episodes.",
                UserWarning,
                stacklevel=2,
            )
        infos[slot]["terminal_observation"] = reset_slot(env, slot, new_obs)
        dones[slot] = True


def _slot_monitor(env: VecEnv, slot: int) -> Monitor | None:
    """
    :return: The ``Monitor`` of a ``DummyVecEnv`` slot (also through SB3's ``VecTransposeImage``), if it has one
        (another process's cannot be reached).
    """
    inner = env.unwrapped
    return unwrap_wrapper(inner.envs[slot], Monitor) if isinstance(inner, DummyVecEnv) else None  # type: ignore[return-value]


def _end_monitor_episode(monitor: Monitor, info: dict[str, Any]) -> dict[str, Any]:
    """
    End the ``Monitor``'s episode as its ``step()`` does when its env truncates one (SB3 2.x): a ``Monitor`` outside
    the cap would otherwise drop the cut episode at the reset, and its file, its ``get_episode_rewards()`` and the
    ``info["episode"]`` of the step would miss it. Its return is the ``Monitor``'s own, before any reward wrapper
    placed after it.

    :param monitor: The slot's ``Monitor``.
    :param info: The info of the slot's last step (``info_keywords`` are read from it).
    :return: The episode info (``r``, ``l``, ``t`` and the ``info_keywords``).
    """
    monitor.needs_reset = True
    ep_rew = sum(monitor.rewards)
    elapsed = time.time() - monitor.t_start
    ep_info = {"r": round(ep_rew, 6), "l": len(monitor.rewards), "t": round(elapsed, 6)}
    for key in monitor.info_keywords:
        ep_info[key] = info[key]
    monitor.episode_returns.append(ep_rew)
    monitor.episode_lengths.append(len(monitor.rewards))
    monitor.episode_times.append(elapsed)
    ep_info.update(monitor.current_reset_info)
    if monitor.results_writer:
        monitor.results_writer.write_row(ep_info)
    return ep_info
