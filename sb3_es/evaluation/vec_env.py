"""Population evaluation on any SB3 VecEnv, in the current process."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, unwrap_vec_normalize

from sb3_es.evaluation.base import Generation, PopulationEvaluator, PopulationResult, StepHook
from sb3_es.evaluation.slot_reset import check_common_seeds, reset_slot
from sb3_es.evaluation.time_limit import end_capped_episodes

#: Observations gathered before they are added to the observation statistics.
OBS_CHUNK_ROWS = 1024


class VecEnvEvaluator(PopulationEvaluator):
    """
    Evaluates a population on an SB3 ``VecEnv`` (``DummyVecEnv``, ``SubprocVecEnv``, ``VecNormalize``, ...).

    Every env slot runs a different candidate and takes the next pending (candidate, episode) job as
    soon as its episode ends; all slots share one batched forward pass per vec step. Slots left without
    a job at the end of the generation run the center policy, whose completed episodes are reported
    as a free evaluation of the mean (``n_steps`` counts their steps too). At the start of each
    generation the VecEnv is re-seeded and reset, so a generation's outcome depends only on the seed
    and the parameters. With the generation's ``reset_seeds``, each candidate episode starts with its slot
    reset with that episode's seed (common random numbers; not through a ``VecEnvWrapper``, which would not see
    the reset). Returns and fitness are the env's own reward: through a ``VecNormalize`` that normalizes rewards, its
    original reward (its scale changes within a generation, and would rank candidates on different scales).

    :param env: The vectorized environment.
    """

    def __init__(self, env: VecEnv) -> None:
        self.env = env

    def _evaluate(self, generation: Generation, step_hook: StepHook | None) -> PopulationResult:
        return self.run(generation, step_hook)

    def run(
        self, generation: Generation, step_hook: StepHook | None = None, linger: Callable[[], bool] | None = None
    ) -> PopulationResult:
        """
        The engine: see :meth:`PopulationEvaluator.evaluate`.

        :param generation: What to run.
        :param step_hook: Called once per vec step; returning False stops the evaluation.
        :param linger: Called once the candidates' episodes have all ended, and again before every further vec step:
            while it returns True, every slot keeps running the center policy. A worker that has finished its
            share uses it to stay busy until the generation's last candidate episode, on any worker, has ended.
        :return: The results.
        """
        network = generation.network  # observation statistics frozen for the generation
        shaping = generation.shaping
        env = self.env
        for name in ("observation_space", "action_space"):
            ours, theirs = getattr(env, name), getattr(network, name)
            if ours != theirs:
                raise ValueError(
                    f"The evaluator's env has {name} {ours}, but the policy was built for {theirs}: give the "
                    "evaluator the same env (and wrappers) as the model. (SB3 wraps a model env with image "
                    "observations in VecTransposeImage: wrap the evaluator's env in it too.)"
                )
        reset_seeds = generation.reset_seeds
        if reset_seeds is not None:
            check_common_seeds(env)
        vec_normalize = unwrap_vec_normalize(env)
        if vec_normalize is not None and not vec_normalize.norm_reward:
            vec_normalize = None  # its rewards are the env's
        n_envs = env.num_envs
        result = generation.empty_result()
        returns, lengths, shaped_returns = result.returns, result.lengths, result.shaped_returns

        params = np.asarray(generation.population, dtype=np.float32)
        center_params = np.asarray(generation.center, dtype=np.float32)
        # Jobs run episode by episode so that every candidate gets its first episode early.
        n_candidates = generation.n_candidates
        pending = deque((c, e) for e in range(generation.n_episodes) for c in range(n_candidates))
        remaining = len(pending)
        slot_job: list[tuple[int, int] | None] = [None] * n_envs
        active = np.zeros(n_envs, dtype=bool)  # slot runs a candidate (not the center policy)
        slot_params = np.repeat(center_params[None], n_envs, axis=0)

        def assign(slot: int) -> None:
            job = pending.popleft() if pending else None
            slot_job[slot] = job
            active[slot] = job is not None
            slot_params[slot] = params[job[0]] if job is not None else center_params

        def start_episode(slot: int) -> None:
            # After assign(): a candidate episode with a reset seed starts from that seed's state.
            job = slot_job[slot]
            if reset_seeds is not None and job is not None:
                reset_slot(env, slot, obs, reset_seeds[job])  # type: ignore[arg-type]

        for slot in range(n_envs):
            assign(slot)
        ep_return = np.zeros(n_envs)
        ep_length = np.zeros(n_envs, dtype=np.int64)
        ep_shaped = np.zeros(n_envs)
        env.seed(generation.seed)
        obs = env.reset()
        for slot in range(n_envs):
            start_episode(slot)
        # The candidates' observations, added to the statistics a chunk at a time (an update per vec step would cost
        # about as much as the forward pass).
        obs_chunk = np.empty((max(OBS_CHUNK_ROWS, n_envs), network.obs_dim))
        seen = 0

        while remaining > 0 or (linger is not None and linger()):
            flat_obs = network.flatten_obs(obs)  # type: ignore[arg-type]
            rows = flat_obs if active.all() else flat_obs[active]
            if seen + len(rows) > len(obs_chunk):
                result.obs_stats.add(obs_chunk[:seen])
                seen = 0
            obs_chunk[seen : seen + len(rows)] = rows
            seen += len(rows)
            actions = network(slot_params, flat_obs)
            obs, rewards, dones, infos = env.step(actions)
            env_rewards = rewards if vec_normalize is None else vec_normalize.get_original_reward()
            result.n_steps += n_envs
            ep_return += env_rewards
            ep_length += 1
            end_capped_episodes(env, generation.max_episode_steps, ep_length, obs, dones, infos)  # type: ignore[arg-type]
            if shaping is not None and shaped_returns is not None:
                ep_shaped += shaping(env_rewards, dones, infos)
            for slot in np.flatnonzero(dones).tolist():
                job = slot_job[slot]
                if job is None:
                    result.center_returns.append(float(ep_return[slot]))
                    result.center_lengths.append(int(ep_length[slot]))
                else:
                    returns[job] = ep_return[slot]
                    lengths[job] = ep_length[slot]
                    if shaped_returns is not None:
                        shaped_returns[job] = ep_shaped[slot]
                    remaining -= 1
                    # The Monitor's episode info, or what was measured here (no Monitor, or an episode cut here).
                    episode = infos[slot].get("episode", {"r": float(ep_return[slot]), "l": int(ep_length[slot])})
                    result.ep_infos.append(episode)
                    if infos[slot].get("is_success") is not None:
                        result.successes.append(bool(infos[slot]["is_success"]))
                ep_return[slot] = 0.0
                ep_length[slot] = 0
                ep_shaped[slot] = 0.0
                assign(slot)
                start_episode(slot)
            if step_hook is not None and not step_hook(n_envs, infos, dones, rewards, obs, actions):
                result.stopped = remaining > 0
                break
        result.obs_stats.add(obs_chunk[:seen])
        return result
