"""The numba ORCA kernel against the per-agent reference twin (RVO2 statement by statement) and pyrvo."""

from __future__ import annotations

import numpy as np
import pytest

from song.pipeline.crowd import _reference as ref
from song.pipeline.crowd.orca import build_obstacles, orca_step
from song.pipeline.crowd.orca_kernel import orca_step_compiled
from tests.pipeline.crowd.test_orca import PARAMS, TWIN_TOL, _agents, _room


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("n", [1, 2, 9, 40, 130])
@pytest.mark.parametrize("walls", [False, True])
def test_kernel_matches_reference_twin(n: int, seed: int, walls: bool) -> None:
    obstacles = build_obstacles(_room()) if walls else None
    args = (*_agents(n, seed), obstacles, PARAMS)
    np.testing.assert_allclose(orca_step_compiled(*args), ref.orca_step_reference(*args), rtol=0, atol=TWIN_TOL)


@pytest.mark.parametrize("seed", range(3))
def test_kernel_matches_vectorised_step_in_dense_crowds(seed: int) -> None:
    """Squeezed agents exercise linearProgram3 with the walls kept hard."""
    pos, vel, pref, radii, speeds = _agents(120, 100 + seed, spread=0.6)
    args = (pos, vel, pref, radii, speeds, build_obstacles(_room()), PARAMS)
    np.testing.assert_allclose(orca_step_compiled(*args), orca_step(*args), rtol=0, atol=TWIN_TOL)
    np.testing.assert_allclose(orca_step_compiled(*args), ref.orca_step_reference(*args), rtol=0, atol=TWIN_TOL)
