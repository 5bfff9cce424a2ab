"""User policies are untrusted: they see copies, and a failing policy fails only its own episode.

- :func:`frozen_copy`: the episode a policy's ``reset`` receives -- a deep copy whose arrays are
  read-only, so a policy cannot move the goal or the pedestrians of the runtime's own copy (from
  which every outcome and metric is computed).
- :func:`call_policy`: runs ``reset``/``act`` under a per-call time limit (SIGALRM, in the main thread
  of the process running the episode; elsewhere the limit is not enforced) and turns an exception,
  ``sys.exit``, a time-out or a malformed command into :class:`PolicyFailure` with a one-line reason.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import signal
import threading
from collections.abc import Callable
from contextlib import contextmanager
from typing import Any

import numpy as np

from song.datasets.bench.types import Episode
from song.errors import SongError

DEFAULT_STEP_TIMEOUT_S = 5.0


class PolicyFailure(SongError):
    """The policy raised, exited, ran past its time limit or returned something that is not a command."""


def _freeze(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            _freeze(getattr(value, f.name))
    elif isinstance(value, list | tuple):
        for item in value:
            _freeze(item)
    elif isinstance(value, dict):
        for item in value.values():
            _freeze(item)
    return value


def frozen_copy(episode: Episode) -> Episode:
    """A deep copy of ``episode`` with every array read-only."""
    return _freeze(copy.deepcopy(episode))


def policy_view(episode: Episode, sensors: tuple[str, ...]) -> Episode:
    """What a policy's ``reset`` receives: the episode as its declared sensors entitle it, frozen.

    Always: the ids, difficulty, start, goal, goal radius, L* and T*, t0 and the runtime parameters.
    With the ``map`` sensor: the static map and the release's planned path too. Never: the
    pedestrians' tracks and avatars (their states reach a policy only through the ``pedestrians``
    sensor, step by step), the grading factors, the reference pedestrian or the predicted encounter.
    """
    mapped = "map" in sensors
    grid = episode.static_map
    blank = type(grid)(np.zeros((1, 1), np.uint8), grid.resolution, grid.origin)
    view = dataclasses.replace(
        episode,
        pedestrians=[],
        avatars=[],
        gaussians_path=None,
        usd_path=None,
        factors={},
        reference_ped_id=-1,
        encounter_time=float("nan"),
        static_map=grid if mapped else blank,
        path=episode.path if mapped else np.zeros((0, 2)),
    )
    return frozen_copy(view)


class _Timeout(BaseException):
    """Raised by the alarm inside the policy call (a BaseException so the policy's `except Exception` cannot swallow it)."""


@contextmanager
def _time_limit(seconds: float | None):
    if not seconds or not math.isfinite(seconds) or threading.current_thread() is not threading.main_thread():
        yield
        return

    def _alarm(signum, frame):
        raise _Timeout

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


def call_policy(call: Callable[..., Any], *args: Any, what: str, timeout_s: float | None) -> Any:
    """``call(*args)`` with the time limit; any failure becomes :class:`PolicyFailure` (``what`` names it)."""
    try:
        with _time_limit(timeout_s):
            return call(*args)
    except _Timeout:
        raise PolicyFailure(f"{what} ran past the {timeout_s:g} s limit") from None
    except SystemExit as exc:
        raise PolicyFailure(f"{what} called sys.exit({exc.code!r})") from None
    except Exception as exc:  # the policy is user code: any error fails its episode only
        raise PolicyFailure(f"{what} raised {type(exc).__name__}: {' '.join(str(exc).split())[:200]}") from None


def as_command(action: Any) -> tuple[float, float]:
    """A policy's return value as a finite (v, ω), or :class:`PolicyFailure` saying what it was."""
    try:
        values = np.asarray(action, dtype=np.float64)
    except Exception:  # a policy's object whose __array__ or __float__ raises: its fault, one line
        values = None
    if values is None or values.shape != (2,) or not all(math.isfinite(v) for v in values):
        shown = repr(action)[:80]
        raise PolicyFailure(f"act() returned {shown}; expected two finite numbers (v m/s, ω rad/s)")
    return float(values[0]), float(values[1])
