"""Write the save files of sb3-es before strategy state version 2 (run with that version's code on the path).

These files were written at commit fcb4e90 with
``PYTHONPATH=<checkout of fcb4e90> python tests/data/legacy/make_legacy.py tests/data/legacy``: each algorithm
trains one generation on Pendulum-v1 (one env), is saved, then trains one more generation; the parameters after
the second generation are stored next to the file, so a test can check that loading and training one more
generation with today's code continues the same run.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from stable_baselines3.common.env_util import make_vec_env

from sb3_es import ARS, CMAES, OpenES

MODELS = {
    "ars": lambda env: ARS("LinearPolicy", env, n_delta=2, seed=0),
    "openes": lambda env: OpenES(
        "LinearPolicy", env, population_size=4, sigma_decay=0.8, learning_rate_decay=0.9, learning_rate=0.05, seed=0
    ),
    "cmaes": lambda env: CMAES("LinearPolicy", env, population_size=4, seed=0),
}

if __name__ == "__main__":
    folder = Path(sys.argv[1])
    for name, make in MODELS.items():
        model = make(make_vec_env("Pendulum-v1", n_envs=1))
        model.learn(1)
        model.save(folder / f"{name}.zip")
        model.learn(1, reset_num_timesteps=False)
        np.save(folder / f"{name}_next.npy", model.policy.parameters_to_vector())
