"""The teleoperation page in headless Chromium on a real release: first frame, key-to-motion latency, steps/s.

    .venv/bin/python benchmarks/teleop.py --bench runs/demo-bench --episode procthor_house_6-001 \
        [--resolution 320x240] [--screenshot docs/figures/teleop.png]

Opens ``song teleop``'s page (Debian's ``chromium`` + ``chromium-driver``, driven by Selenium), holds W
for 3 s, then A for 1 s, and reports: seconds from opening the page to its first frame, milliseconds
from the key press to the first step run with the forward command, and control steps per second of
wall time while driving (the control rate is 10 Hz). Targets (the issue): first frame ≤ 2 s,
latency ≤ 150 ms, 10 steps/s at 320×240 on 2 cores.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.cli.common import parse_size  # noqa: E402
from song.runtime.teleop import run_teleop  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", required=True)
    parser.add_argument("--episode", required=True)
    parser.add_argument("--resolution", default=None, help="WxH (default: chosen by song teleop)")
    parser.add_argument("--screenshot", type=Path, default=None)
    args = parser.parse_args()
    from selenium import webdriver
    from selenium.webdriver.common.action_chains import ActionChains

    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium") or shutil.which("chromium-browser")
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=820,700"):
        options.add_argument(flag)
    browser = webdriver.Chrome(options=options, service=webdriver.ChromeService(shutil.which("chromedriver")))
    ready: dict = {}
    size = parse_size(args.resolution, "--resolution") if args.resolution else None
    out = Path(tempfile.mkdtemp(prefix="song-teleop-"))
    thread = threading.Thread(
        target=run_teleop,
        args=(args.bench, out, [args.episode], "test", size, 0, lambda u: ready.setdefault("url", u), 60),
        daemon=True,
    )
    thread.start()
    while "url" not in ready:
        time.sleep(0.05)
    opened = time.monotonic()
    browser.get(ready["url"])
    while browser.execute_script("return window.songFrames") == 0:
        time.sleep(0.01)
    first_frame = time.monotonic() - opened
    pressed = time.monotonic()
    ActionChains(browser).key_down("w").perform()
    while (browser.execute_script("return window.songLast.command") or [0, 0])[0] <= 0:
        time.sleep(0.003)
    latency = time.monotonic() - pressed
    t0, w0 = browser.execute_script("return window.songLast.t"), time.monotonic()
    time.sleep(1.0)
    if args.screenshot:  # mid-drive
        args.screenshot.parent.mkdir(parents=True, exist_ok=True)
        browser.get_screenshot_as_file(str(args.screenshot))
    time.sleep(2.0)
    t1, w1 = browser.execute_script("return window.songLast.t"), time.monotonic()
    ActionChains(browser).key_up("w").key_down("a").perform()
    time.sleep(1.0)
    ActionChains(browser).key_up("a").perform()
    status = browser.execute_script("return document.getElementById('status').textContent")
    browser.quit()
    emit(
        {
            "episode": args.episode,
            "status_line": status,
            "first_frame_s": round(first_frame, 2),
            "key_to_motion_ms": round(1000 * latency),
            "steps_per_s": round((t1 - t0) * 10.0 / (w1 - w0), 2),
            "targets": {"first_frame_s": 2.0, "key_to_motion_ms": 150, "steps_per_s": 10.0},
        }
    )


if __name__ == "__main__":
    main()
