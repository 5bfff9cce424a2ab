"""Teleoperation in a real browser: headless Chromium opens the page, holds keys, and the robot obeys."""

from __future__ import annotations

import dataclasses
import json
import shutil
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from song.datasets.bench import open_benchmark
from song.runtime.teleop import command_from_keys

GOLDEN = Path(__file__).resolve().parents[1] / "artifacts" / "bench_golden"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")


def test_keys_map_to_commands_within_the_limits() -> None:
    assert command_from_keys({"w"}, 0.5, 0.8) == (0.5, 0.0)
    assert command_from_keys({"arrowup", "a"}, 0.5, 0.8) == (0.5, 0.8)
    assert command_from_keys({"w", "s", "d"}, 0.5, 0.8) == (0.0, -0.8)  # stop wins over forward
    assert command_from_keys({"a", "d"}, 0.5, 0.8) == (0.0, 0.0)
    assert command_from_keys(set(), 0.5, 0.8) == (0.0, 0.0)


def _browser():
    pytest.importorskip("starlette", reason="song[teleop] is not installed")
    pytest.importorskip("uvicorn", reason="song[teleop] is not installed")
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium (dev extra) is not installed")
    if not CHROMIUM or not DRIVER:
        pytest.skip("Chromium or chromedriver is not installed (Debian: apt-get install chromium chromium-driver)")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        options.add_argument(flag)
    return webdriver.Chrome(options=options, service=webdriver.ChromeService(executable_path=DRIVER))


@pytest.mark.parametrize("reactive", [False, True], ids=["replay", "reactive"])
def test_a_person_drives_an_episode_from_the_page(tmp_path: Path, reactive: bool) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    from song.runtime.teleop import run_teleop

    browser = _browser()
    bench = open_benchmark(GOLDEN)
    robot = bench.params.robot.model_copy(update={"max_steps": 45})  # 4.5 s of driving keeps the test short
    params = dataclasses.replace(bench.params, robot=robot)
    ready: dict = {}
    out = tmp_path / "teleop"
    result: dict = {}

    def serve() -> None:
        try:
            result["summary"] = run_teleop(
                str(GOLDEN), out, ["scene_1-001"], resolution=(320, 240), on_ready=lambda u: ready.setdefault("url", u),
                connect_timeout_s=60, params=params, reactive=reactive,
            )  # fmt: skip
        except BaseException as exc:  # surfaced by the assertions below
            result["error"] = exc

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 30
        while "url" not in ready and thread.is_alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert "url" in ready, result.get("error")
        wrong = ready["url"].split("?")[0] + "?token=nope"
        browser.get(wrong)
        assert "wrong token" in browser.page_source  # the token guards the page
        opened = time.monotonic()
        browser.get(ready["url"])
        while browser.execute_script("return window.songFrames") == 0:
            assert time.monotonic() - opened < 10, "no frame arrived"
            time.sleep(0.02)
        first_frame_s = time.monotonic() - opened
        first = browser.execute_script("return window.songLast")
        # hold W: measure how long until a step runs with the forward command
        pressed = time.monotonic()
        ActionChains(browser).key_down("w").perform()
        while (browser.execute_script("return window.songLast.command") or [0, 0])[0] <= 0:
            assert time.monotonic() - pressed < 3, "the robot never got the forward command"
            time.sleep(0.005)
        latency_s = time.monotonic() - pressed
        t0, w0 = browser.execute_script("return window.songLast.t"), time.monotonic()
        time.sleep(1.5)
        t1, w1 = browser.execute_script("return window.songLast.t"), time.monotonic()
        ActionChains(browser).key_up("w").key_down("a").perform()
        time.sleep(0.6)
        ActionChains(browser).key_up("a").perform()
        later = browser.execute_script("return window.songLast")
        assert later["frame"] != first["frame"], later.get("outcome")  # the view changed as the robot moved
        thread.join(timeout=30)
        assert not thread.is_alive() and "error" not in result, result.get("error")
        browser.get_screenshot_as_file(str(tmp_path / "page.png"))
    finally:
        browser.quit()
    steps_per_s = (t1 - t0) * float(robot.control_hz) / (w1 - w0)  # scenario time advances 1/control_hz a step
    measured = f"first frame {first_frame_s:.2f} s, key-to-motion {1000 * latency_s:.0f} ms, {steps_per_s:.1f} steps/s"
    sys.stdout.write(f"teleop: {measured}\n")  # shown with -s; the note quotes it
    assert first_frame_s < 5.0 and latency_s < 0.5 and steps_per_s > 5.0  # generous bounds for a loaded CI machine
    name = "human-reactive" if reactive else "human"
    assert sorted(p.name for p in out.glob("human*")) == [f"{name}.{ext}" for ext in ("json", "md", "parquet")]
    summary = json.loads((out / f"{name}.json").read_text())
    assert summary["policy"] == "human" and summary["policy_kind"] == "human_teleop"
    assert summary["overrides"] == {"robot.max_steps": [200, 45]} and summary["official"] is False
    assert summary["pedestrians"] == ("reactive" if reactive else "replay")
    import pyarrow.parquet as pq

    (row,) = pq.read_table(out / f"{name}.parquet").to_pylist()
    trajectory = np.array(row["trajectory"])
    assert row["length"] > 0.3 and abs(trajectory[-1, 2] - trajectory[0, 2]) > 0.1  # drove forward, then turned
    info = json.loads((out / "dataset" / "meta" / "info.json").read_text())
    assert info["total_episodes"] == 1 and info["song"]["policy"] == "human"
    assert info["song"]["pedestrians"] == ("reactive" if reactive else "replay")
    assert (out / "dataset" / "videos").is_dir()
