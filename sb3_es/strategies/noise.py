"""A shared table of Gaussian noise, from which ES strategies read perturbations as slices.

As in the OpenAI ES and ARS reference implementations, a candidate is described by an offset into the
table and a signed scale, so a distributed evaluator can ship a few bytes per candidate instead of a
full parameter vector. Pure array math: no environment, no Ray.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


class SharedNoiseTable:
    """
    A block of standard normal noise, generated from a seed, from which perturbations are read as slices.

    As in the OpenAI ES and ARS reference implementations, a strategy can describe a candidate as
    ``center + scale * table[offset:offset + num_params]`` and send only ``offset`` and ``scale``: the table
    is put once in Ray's object store and shared by every actor of a node. Pickling keeps only the size and
    seed (the table is regenerated on unpickling), so a strategy holding one saves in a few bytes.

    :param size: Number of float32 values (``2**25`` = 128 MiB by default).
    :param seed: Seed of the generator that fills the table.
    """

    def __init__(self, size: int = 2**25, seed: int = 0) -> None:
        if not (float(size).is_integer() and size >= 1):
            raise ValueError(f"size={size!r}: the noise table needs a whole, positive number of values.")
        self.size = int(size)
        self.seed = int(seed)
        self.noise = np.random.default_rng(self.seed).standard_normal(self.size, dtype=np.float32)
        self.noise.flags.writeable = False

    @property
    def key(self) -> tuple[int, int]:
        """:return: ``(size, seed)``, which identifies the table's content."""
        return self.size, self.seed

    def get(self, offset: int, dim: int) -> np.ndarray:
        """
        :param offset: Start of the slice.
        :param dim: Length of the slice.
        :return: A read-only view ``table[offset:offset + dim]``.
        """
        return self.noise[offset : offset + dim]

    def check_fits(self, dim: int, n: int = 1) -> None:
        """
        :param dim: Length of each slice (the number of parameters).
        :param n: Number of distinct slices needed (the perturbations of a generation).
        :raises ValueError: Naming ``noise_table_size`` and the fix when the table holds fewer than ``n`` slices.
        """
        if dim > self.size:
            raise ValueError(
                f"noise_table_size={self.size} is smaller than one perturbation ({dim} parameters): raise it well "
                f"above {dim} (tables of millions of values are usual), or pass None to draw every perturbation afresh."
            )
        if self.size - dim + 1 < n:  # fewer slices than perturbations: some candidates would surely share one
            raise ValueError(
                f"The noise table ({self.size} values) holds {self.size - dim + 1} distinct perturbations of {dim} "
                f"parameters, fewer than the {n} of a generation: raise noise_table_size well above {dim + n - 1} "
                "(tables of millions of values are usual), or pass None to draw every perturbation afresh."
            )

    def sample_offsets(self, rng: np.random.Generator, dim: int, n: int) -> np.ndarray:
        """
        :param rng: Random generator (the strategy's, so runs stay reproducible).
        :param dim: Length of each slice (the number of parameters).
        :param n: Number of offsets.
        :return: ``n`` offsets such that every slice fits in the table, drawn independently, as in OpenAI's ES: in a
            table not much larger than ``dim + n`` two candidates may share a direction (the check only makes sure
            there are ``n`` distinct slices to draw from).
        """
        self.check_fits(dim, n)
        return rng.integers(0, self.size - dim + 1, size=n)

    def __getstate__(self) -> dict[str, int]:
        return {"size": self.size, "seed": self.seed}

    def __setstate__(self, state: dict[str, int]) -> None:
        self.__init__(state["size"], state["seed"])  # type: ignore[misc]


def noise_rows(noise: np.ndarray, center: np.ndarray, offsets: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """
    Rebuild candidates ``center + scales[i] * noise[offsets[i]:offsets[i] + dim]`` (float64).

    :param noise: The noise table's values.
    :param center: Center ``(dim,)``.
    :param offsets: Offsets ``(n,)``.
    :param scales: Signed scales ``(n,)`` (e.g. ``+sigma`` and ``-sigma`` for antithetic pairs).
    :return: Candidates ``(n, dim)``.
    """
    center = np.asarray(center, dtype=np.float64)
    rows = np.empty((len(offsets), center.shape[0]))
    for i, (offset, scale) in enumerate(zip(np.asarray(offsets).tolist(), np.asarray(scales).tolist())):
        rows[i] = noise_row(noise, center, offset, scale)
    return rows


def noise_row(noise: np.ndarray, center: np.ndarray, offset: int, scale: float) -> np.ndarray:
    """
    :param noise: The noise table's values.
    :param center: Center ``(dim,)``, float64.
    :param offset: Offset of the candidate's noise.
    :param scale: Signed scale of the candidate's noise.
    :return: The candidate ``center + scale * noise[offset:offset + dim]`` (float64).
    """
    return center + scale * noise[offset : offset + center.shape[0]].astype(np.float64)


@dataclass
class NoiseTablePopulation:
    """
    A population described by offsets into a :class:`SharedNoiseTable`: row ``i`` is
    ``center + scales[i] * table[offsets[i]:offsets[i] + dim]``.

    It behaves as the dense ``(n, dim)`` array for the local engine (``shape``, ``np.asarray``), and
    the sharded evaluators (Ray actors, worker processes) send only ``offsets`` and ``scales`` to their workers.

    :param table: The noise table.
    :param center: Center of the population ``(dim,)``.
    :param offsets: Offset of each candidate's noise ``(n,)``.
    :param scales: Signed scale of each candidate's noise ``(n,)``.
    """

    table: SharedNoiseTable
    center: np.ndarray
    offsets: np.ndarray
    scales: np.ndarray
    _dense: np.ndarray | None = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        """:return: ``(n_candidates, dim)``, as the dense population."""
        return len(self.offsets), int(np.asarray(self.center).shape[0])

    def __len__(self) -> int:
        return len(self.offsets)

    def dense(self) -> np.ndarray:
        """:return: The candidates as a float64 array ``(n, dim)`` (computed once)."""
        if self._dense is None:
            self._dense = noise_rows(self.table.noise, self.center, self.offsets, self.scales)
        return self._dense

    def rows(self, indices: np.ndarray) -> np.ndarray:
        """
        :param indices: Which candidates.
        :return: Those candidates, float64, equal to ``dense()[indices]`` (without building the others).
        """
        if self._dense is not None:
            return self._dense[indices]
        return noise_rows(self.table.noise, self.center, self.offsets[indices], self.scales[indices])

    def row(self, index: int) -> np.ndarray:
        """
        :param index: Which candidate.
        :return: That candidate alone, float64, equal to ``dense()[index]``.
        """
        center = np.asarray(self.center, dtype=np.float64)
        return noise_row(self.table.noise, center, int(self.offsets[index]), float(self.scales[index]))

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        return self.dense() if dtype is None else self.dense().astype(dtype)
