"""``song eval --isolate``: the policy runs in a process of its own and sees only what is sent to it.

In-process, a policy is Python code in the evaluation process: it can walk the call stack or the
garbage collector to the runner and read what it should not, and a call that loops inside C code
ignores the step alarm. Isolated, the policy lives in a spawned child process; the parent sends it the
episode as its sensors entitle it to (:func:`song.runtime.guard.policy_view`) and each step's
observation over a pipe, and gets back a command the child has already turned into two floats (so no
object of the policy's is ever touched in the parent). A call that takes longer than the step time
limit kills the child: its episode ends as ``error`` and the next episode starts a fresh child.
"""

from __future__ import annotations

import math
import multiprocessing
from typing import Any

from song.runtime.guard import PolicyFailure, as_command

KILL_WAIT_S = 2.0  # how long a killed child may take to go
STARTUP_S = 120.0  # a child's start (a fresh interpreter importing song and the policy) is not a step
NO_LIMIT_S = 3600.0  # the wait for a call when no step limit is set


def _serve(conn, spec: str) -> None:  # pragma: no cover - runs in the child process
    """The child: build the policy from ``spec`` and answer ``sensors``, ``reset`` and ``act`` messages."""
    from song.runtime.policies import load_policy, policy_info, policy_sensors

    try:  # ready: the policy's module is imported and its sensors are known
        first = load_policy(spec)
        conn.send(("ok", (tuple(policy_sensors(first)), policy_info(first))))
    except BaseException as exc:
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    policy = None
    while True:
        try:
            kind, payload = conn.recv()
        except (EOFError, OSError):
            return
        try:
            if kind == "reset":
                policy = load_policy(spec)  # a fresh policy per episode, as in-process
                policy.reset(payload)
                reply = None
            elif kind == "act":
                reply = as_command(policy.act(payload))
            else:
                return
            conn.send(("ok", reply))
        except BaseException as exc:  # everything the policy does wrong goes back as one line
            conn.send(("error", f"{type(exc).__name__}: {exc}"))


class IsolatedPolicy:
    """A policy in a child process (see the module docstring); the same ``reset``/``act`` as any policy.

    Args:
        spec: the policy's name (a plugin, ``module:Class`` or ``file.py:Class``).
        timeout_s: the most one call may take before the child is killed (None or inf: no limit).
    """

    def __init__(self, spec: str, timeout_s: float | None) -> None:
        self.spec = spec
        self.timeout_s = timeout_s if timeout_s and math.isfinite(timeout_s) else NO_LIMIT_S
        self._process = None
        self._conn = None
        self.sensors: tuple[str, ...] = ()
        self.info: dict[str, Any] = {}
        self._start()

    def _start(self) -> None:
        """Spawn the child and wait (up to ``STARTUP_S``, not the step limit) until it has loaded the policy."""
        context = multiprocessing.get_context("spawn")
        self._conn, child = context.Pipe()
        self._process = context.Process(target=_serve, args=(child, self.spec), daemon=True)
        self._process.start()
        child.close()
        sensors, info = self._reply("loading the policy", STARTUP_S)
        self.sensors, self.info = tuple(sensors), dict(info)

    def _call(self, kind: str, payload: Any, what: str) -> Any:
        if self._process is None or not self._process.is_alive():
            self._start()
        self._conn.send((kind, payload))
        return self._reply(what, self.timeout_s)

    def _reply(self, what: str, wait_s: float) -> Any:
        if not self._conn.poll(wait_s):
            self.close()
            raise PolicyFailure(f"{what} took longer than {wait_s:g} s (the isolated policy was stopped)")
        try:
            status, reply = self._conn.recv()
        except (EOFError, OSError):
            self.close()
            raise PolicyFailure(f"{what}: the isolated policy's process ended") from None
        if status != "ok":
            raise PolicyFailure(f"{what} failed: {reply}")
        return reply

    def reset(self, episode) -> None:
        """Send the episode (already reduced to what the sensors entitle) and wait for the child."""
        self._call("reset", episode, "reset()")

    def act(self, observation: dict[str, Any]) -> tuple[float, float]:
        """The child's command for this observation, as two floats."""
        return tuple(self._call("act", observation, "act()"))

    def close(self) -> None:
        """Stop the child (killed if it does not go)."""
        if self._process is not None:
            if self._process.is_alive():
                self._process.kill()
            self._process.join(KILL_WAIT_S)
        if self._conn is not None:
            self._conn.close()
        self._process = self._conn = None
