"""The threading policy: numba's OpenMP layer with passive waiting, set at import, the user's choice kept."""

from __future__ import annotations

import os
import subprocess
import sys

PROBE = """
import json, os
import song
import numpy as np
import numba
from song.render import render, robot_camera
from tests.render.test_render import _random_scene
render(_random_scene(0, n=50), robot_camera(0.0, 0.0, 0.0, 0.8, 70.0, 16, 12), "numba")  # a parallel launch
print(json.dumps({"layer": numba.threading_layer(), "wait": os.environ.get("OMP_WAIT_POLICY")}))
"""


def _probe(**env: str) -> dict:
    import json

    clean = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "NUMBA_THREADING_LAYER")}
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env={**clean, **env},
                          cwd=os.path.dirname(os.path.dirname(__file__)), timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_configured_layer_is_the_one_in_use() -> None:
    assert _probe() == {"layer": "omp", "wait": "PASSIVE"}


def test_the_user_s_choice_is_kept() -> None:
    assert _probe(NUMBA_THREADING_LAYER="workqueue", OMP_WAIT_POLICY="ACTIVE") == {
        "layer": "workqueue",
        "wait": "ACTIVE",
    }
