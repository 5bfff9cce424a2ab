"""``song teleop``: a person drives the robot from a browser page (the paper's human upper bound).

The page (served on 127.0.0.1 only; a random token in its URL) shows the robot camera's RGB at the
control rate and the goal's distance and bearing, nothing else, as the paper's operators saw; W/A/S/D
or the arrow keys drive within the robot's limits. Each episode is attempted once. The person is a
policy like any other (:class:`HumanPolicy`, ``sensors = ("state", "rgb")``): the same runtime as
``song eval`` scores the runs (``OUT/human.json``, ``.parquet``, ``.md``) and the same recorder as
``song collect`` writes them as a LeRobot dataset (``OUT/dataset``), so teleoperated demonstrations
mix with planner ones.

The web stack is Starlette on uvicorn with a WebSocket (``pip install 'song[teleop]'``): the episode
loop runs in the calling thread and hands frames to the server thread through :class:`TeleopLink`.
Time: every step waits until one control period (0.1 s) has passed since the last, so the robot
moves in real time while the machine renders fast enough; the camera resolution is chosen before
the first episode as the largest of 320×240, 240×180 and 160×120 whose render takes at most 70 ms
here (or fixed with ``--resolution``), and the page says which, with the rate it achieves.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
import secrets
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from song.errors import MissingDependencyError, SongError

PAGE = Path(__file__).with_name("teleop_page.html")
CANDIDATE_SIZES = ((320, 240), (240, 180), (160, 120))
RENDER_BUDGET_S = 0.07  # of the 0.1 s control period; the rest goes to JPEG, the socket and the browser
RESULT_PAUSE_S = 1.5  # the outcome stays on the page this long before the next episode
FORWARD = {"w", "arrowup"}
STOP = {"s", "arrowdown"}
LEFT = {"a", "arrowleft"}
RIGHT = {"d", "arrowright"}


def command_from_keys(keys: set[str], max_speed_mps: float, max_yaw_rate_rad_s: float) -> tuple[float, float]:
    """(v, ω) for the keys held: forward at the speed limit, turning at the yaw-rate limit; stop wins."""
    v = max_speed_mps if keys & FORWARD and not keys & STOP else 0.0
    turn = (1.0 if keys & LEFT else 0.0) - (1.0 if keys & RIGHT else 0.0)
    return v, turn * max_yaw_rate_rad_s


class TeleopLink:
    """What the episode loop and the web server share: the latest message out, the keys held, the client."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.connected = threading.Event()
        self.closed = threading.Event()
        self._keys: set[str] = set()
        self._message: dict[str, Any] = {"status": "waiting for the first episode"}
        self.version = 0

    def publish(self, **message: Any) -> None:
        """Replace the message the page gets next (merged with the fields not given)."""
        with self._lock:
            self._message = {**self._message, **message}
            self.version += 1

    def message(self) -> tuple[int, str]:
        """(version, JSON text) of the current message."""
        with self._lock:
            return self.version, json.dumps(self._message)

    def set_keys(self, keys: Any) -> None:
        """Keys the page says are held (unknown entries are ignored)."""
        known = FORWARD | STOP | LEFT | RIGHT
        with self._lock:
            self._keys = {str(k).lower() for k in keys if str(k).lower() in known} if isinstance(keys, list) else set()

    def keys(self) -> set[str]:
        """The keys held now."""
        with self._lock:
            return set(self._keys)


class HumanPolicy:
    """The person at the page, as a policy: ``act`` shows the frame and returns the keys' command.

    It keeps the control rate in wall time: ``act`` returns one control period after the previous call.
    """

    sensors = ("state", "rgb")

    def __init__(self, link: TeleopLink, status: str = "") -> None:
        self.link = link
        self.status = status

    def reset(self, episode: Any) -> None:
        """Read the robot's limits; the clock starts at the first step."""
        robot = episode.params.robot
        self.limits = (float(robot.max_speed_mps), math.radians(float(robot.max_yaw_rate_deg_s)))
        self.period = 1.0 / float(robot.control_hz)
        self.next_tick = None
        self.rates: list[float] = []

    def act(self, observation: dict[str, Any]) -> tuple[float, float]:
        """Send the camera image and the relative goal; wait for the tick; the command of the keys held."""
        import cv2

        ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(np.asarray(observation["rgb"]), cv2.COLOR_RGB2BGR))
        state = observation["state"]
        now = time.perf_counter()
        if self.next_tick is not None:
            self.rates.append(now)
        rate = (len(self.rates) - 1) / (self.rates[-1] - self.rates[0]) if len(self.rates) > 5 else None
        status = self.status + (f" · {rate:.1f} steps/s" if rate else "")
        self.link.publish(
            frame=base64.b64encode(jpeg.tobytes()).decode() if ok else None,
            goal=[float(v) for v in state["goal_polar"]],
            t=float(np.asarray(state["t"]).reshape(-1)[0]),
            status=status,
            outcome=None,
        )
        self.next_tick = (now if self.next_tick is None else self.next_tick) + self.period
        time.sleep(max(0.0, self.next_tick - time.perf_counter()))
        command = command_from_keys(self.link.keys(), *self.limits)
        self.link.publish(command=list(command))
        return command


def _app(link: TeleopLink, token: str):
    try:
        from starlette.applications import Starlette
        from starlette.responses import HTMLResponse, PlainTextResponse
        from starlette.routing import Route, WebSocketRoute
    except ImportError as exc:
        raise MissingDependencyError("starlette", "teleop") from exc
    import asyncio

    async def page(request):
        if not secrets.compare_digest(request.query_params.get("token", ""), token):
            return PlainTextResponse("missing or wrong token", status_code=403)
        return HTMLResponse(PAGE.read_text(encoding="utf-8"))

    async def socket(websocket):
        if not secrets.compare_digest(websocket.query_params.get("token", ""), token):
            await websocket.close(code=1008)
            return
        await websocket.accept()
        link.connected.set()

        async def receive() -> None:
            while True:
                try:
                    data = json.loads(await websocket.receive_text())
                except (ValueError, TypeError):
                    continue
                link.set_keys(data.get("keys") if isinstance(data, dict) else None)

        reader = asyncio.create_task(receive())
        seen = -1
        try:
            while not link.closed.is_set() and not reader.done():
                version, text = link.message()
                if version != seen:
                    seen = version
                    await websocket.send_text(text)
                await asyncio.sleep(0.005)
        finally:
            reader.cancel()
            link.set_keys([])
            try:
                await websocket.close()
            except RuntimeError:
                pass

    return Starlette(routes=[Route("/", page), WebSocketRoute("/ws", socket)])


class TeleopServer:
    """The page's server on 127.0.0.1 in a daemon thread; ``url`` carries the token."""

    def __init__(self, link: TeleopLink, port: int = 0) -> None:
        try:
            import uvicorn
        except ImportError as exc:
            raise MissingDependencyError("uvicorn", "teleop") from exc
        self.token = secrets.token_urlsafe(16)
        config = uvicorn.Config(
            _app(link, self.token), host="127.0.0.1", port=port, log_level="warning", ws="websockets-sansio"
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True, name="song-teleop")
        self.thread.start()
        deadline = time.monotonic() + 10.0
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise SongError(f"teleop: the web server did not start on 127.0.0.1:{port}")
            time.sleep(0.02)
        self.port = self.server.servers[0].sockets[0].getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}/?token={self.token}"

    def close(self) -> None:
        """Stop serving."""
        self.server.should_exit = True
        self.thread.join(timeout=5.0)


def choose_resolution(bench: Any, episode: Any) -> tuple[int, int]:
    """The largest candidate size whose render (median of 3 after one warm-up) fits the render budget here."""
    from song.runtime.robot import Pose
    from song.runtime.vision import SceneView

    pose = Pose(float(episode.start_xy[0]), float(episode.start_xy[1]), float(episode.start_yaw))
    view = SceneView("auto", bench.params.camera.model)  # the renderer the camera sensors will use
    view.reset(episode)  # the scene is loaded once for every candidate
    for width, height in CANDIDATE_SIZES:
        times = []
        for k in range(4):
            start = time.perf_counter()
            view.render(pose, float(episode.t0) + 0.1 * k, width, height)
            times.append(time.perf_counter() - start)
        if float(np.median(times[1:])) <= RENDER_BUDGET_S:
            return width, height
    return CANDIDATE_SIZES[-1]


def run_teleop(
    bench_path: str,
    out: str | Path,
    episode_ids: list[str] | None = None,
    split: str = "test",
    resolution: tuple[int, int] | None = None,
    port: int = 0,
    on_ready: Callable[[str], None] | None = None,
    connect_timeout_s: float = 600.0,
    params: Any = None,
    reactive: bool = False,
) -> dict[str, Any]:
    """Serve the page, wait for it, run each episode once with the person driving; score and record them.

    Args:
        bench_path: the release.
        out: results folder (``human.*`` and ``dataset/`` inside; must not hold a teleop dataset yet).
        episode_ids: episodes to drive (default: every episode of ``split``).
        split: which split's episodes when ``episode_ids`` is not given.
        resolution: camera size; None chooses the largest that renders in time here.
        port: 0 for any free port.
        on_ready: called with the page's URL once it is served.
        connect_timeout_s: how long to wait for the page to be opened.
        params: runtime parameters instead of the release's (recorded as overrides: unofficial).
        reactive: pedestrians near the robot avoid it (:mod:`song.runtime.reactive`; results filed as
            ``human-reactive.*``, unofficial, and the mode recorded in the dataset).

    Returns:
        The results summary (as ``song eval`` writes it).
    """
    from song.datasets.bench import open_benchmark
    from song.runtime.collect import LOCK_FILE, record_rollout, refuse_non_empty
    from song.runtime.evaluate import EvalSetup, write_results
    from song.runtime.lerobot import write_dataset
    from song.util import folder_lock

    bench = open_benchmark(bench_path)
    bench.require_intact(False)
    chosen = [bench.episode(e) for e in episode_ids] if episode_ids else list(bench.episodes(split=split))
    if not chosen:
        raise SongError(f"{bench_path}: no '{split}' episodes to drive")
    out = Path(out)
    dataset = out / "dataset"
    refuse_non_empty(dataset, "teleop")  # before anyone drives: the runs would have nowhere to go
    params = params or bench.params
    released, used = bench.params.to_json(), params.to_json()
    overrides = {
        f"{section}.{key}": [released[section][key], value]
        for section, values in used.items()
        if isinstance(values, dict)
        for key, value in values.items()
        if released.get(section, {}).get(key) != value
    }
    episodes = [dataclasses.replace(e, params=params) for e in chosen]
    width, height = resolution or choose_resolution(bench, episodes[0])
    link = TeleopLink()
    server = TeleopServer(link, port)
    try:
        if on_ready:
            on_ready(server.url)
        if not link.connected.wait(connect_timeout_s):
            raise SongError(f"teleop: nobody opened {server.url} within {connect_timeout_s:.0f} s")
        camera = {"width": width, "height": height}
        status = f"camera {width}×{height}, control rate {params.robot.control_hz:g} Hz"
        records, results = [], []
        for index, episode in enumerate(episodes):
            link.publish(episode=episode.episode_id, index=index, total=len(episodes), outcome=None)
            human = HumanPolicy(link, status)
            record, result = record_rollout(
                bench, episode, human, ("state", "rgb"), camera, step_timeout_s=None, reactive=reactive
            )
            records.append(record)
            results.append(result)
            link.publish(outcome=result.outcome, status=f"{status} · episode {index + 1} of {len(episodes)} done")
            time.sleep(RESULT_PAUSE_S)
        link.publish(status="all episodes done: results written", frame=None)
    finally:
        link.closed.set()
        server.close()
    sensors = ("state", "rgb")
    setup = EvalSetup("human", sensors, params, overrides, {"camera": camera}, float("inf"), False, False,
                      {"policy_kind": "human_teleop", "camera": f"{width}x{height}"}, reactive)  # fmt: skip
    summary = write_results(out, setup, results, bench)
    dataset.mkdir(parents=True, exist_ok=True)
    with folder_lock(dataset / LOCK_FILE, "dataset folder"):
        refuse_non_empty(dataset, "teleop")  # again under the lock
        about = {"release": str(bench.version), "fingerprint": bench.info.fingerprint, "policy": "human",
                 "split": split, "keep": "all", "rollouts": len(records),
                 "successes": sum(r["outcome"] == "success" for r in records), "release_check": "ok", "ablation": None,
                 "pedestrians": "reactive" if reactive else "replay"}  # fmt: skip
        write_dataset(dataset, records, float(params.robot.control_hz), split, about)
    return summary
