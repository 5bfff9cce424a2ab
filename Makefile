# Fresh machine: `make demo` (set up + run the main job on the sample scenes) or `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
SONG := $(VENV)/bin/song
STAMP := $(VENV)/.installed-stamp
RUN ?= runs/demo
BENCH ?= runs/demo-bench
SAMPLES ?= datasets/sample_scenes
SCENES ?= runs/scenes

.PHONY: setup demo test test-lerobot test-people lerobot-env api lint format bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first, pinned: the local CPU wheel (an unpinned torch pulls a multi-GB CUDA build)
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[all,dev]'
	# third-party reference implementations for tests/benchmarks; their extra deps are not needed
	$(PY) -m pip install --quiet --no-deps pyrvo==0.4.3 pynavmesh==1.2.5
	# headless Chromium for the teleoperation page's browser test (Debian's packages; skipped with a reason elsewhere)
	command -v chromium >/dev/null || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && \
		(apt-get install -y -q chromium chromium-driver >/dev/null 2>&1 || \
		 (apt-get update -q >/dev/null 2>&1 && apt-get install -y -q chromium chromium-driver >/dev/null 2>&1)); } || \
		echo "chromium not installed: the teleoperation browser test will be skipped"
	touch $(STAMP)

setup: $(STAMP)

EVAL ?= runs/demo-eval
FIGURES ?= runs/demo-figures
EPISODES ?= 120

demo: setup
	# the shipped samples carry geometry only; their Gaussian scenes are synthesised here (~2 s each)
	$(SONG) scenes splat $(SAMPLES) --out $(SCENES) --force
	$(SONG) scenes check $(SCENES)
	$(SONG) synth --scenes $(SCENES) --out $(RUN) --workers 2
	$(SONG) grade --run $(RUN) --episodes $(EPISODES) --workers 2
	rm -rf $(BENCH)
	SOURCE_DATE_EPOCH=1700000000 $(SONG) export-bench --run $(RUN) --bench $(BENCH) --version 1.0.0 --notes "make demo"
	$(SONG) bench verify $(BENCH)
	$(SONG) eval --bench $(BENCH) --policy straight --policy astar --policy social --out $(EVAL) --workers 2
	# the avatar-free ablation of the map baselines: results.md shows its rows beside the main ones
	$(SONG) eval --bench $(BENCH) --policy straight --policy astar --no-avatars --out $(EVAL) --workers 2
	# the vision baseline renders every step: a first slice of the release at 160x120 keeps the demo short
	$(SONG) eval --bench $(BENCH) --policy depth --resolution 160x120 --limit 8 --out $(EVAL)-depth --workers 2
	$(SONG) viz bench --bench $(BENCH) --out $(FIGURES) --results $(EVAL)/straight.json --results $(EVAL)/astar.json --results $(EVAL)/social.json
	$(SONG) viz scene $(SCENES)/procthor_house_6 --out $(FIGURES)/scene.png
	$(SONG) viz crowd --run $(RUN) --scene procthor_house_6 --out $(FIGURES)
	$(SONG) viz episode --bench $(BENCH) --episode procthor_house_6-001 --results $(EVAL)/social.parquet --out $(FIGURES)
	$(SONG) viz avatar --out $(FIGURES)/avatars.png --count 6 --gallery $(FIGURES)/avatar_gallery.png
	$(SONG) viz pov --bench $(BENCH) --episode procthor_house_6-001 --policy depth --out $(FIGURES)
	$(SONG) viz view $(SCENES)/procthor_house_6 --out $(FIGURES)/procthor_house_6-view.png
	@echo "results: $(EVAL)/results.md  figures: $(FIGURES)/"

test: setup
	$(VENV)/bin/ruff check song tests benchmarks
	$(VENV)/bin/ruff format --check song tests benchmarks
	$(MAKE) api
	$(VENV)/bin/pytest -q -m "not slow"

# LeRobot's own loader reads `song collect`'s datasets (tests/runtime/test_lerobot.py): lerobot 0.4.4 from
# PyPI in its own environment, with the torch, torchvision and torchcodec it pins (never a dependency of song);
# FFmpeg's libraries for torchcodec from Debian when we are root (without them only the pyav reader is tested)
LEROBOT_ENV := build/bench-envs/lerobot
$(LEROBOT_ENV)/.installed-stamp:
	$(PYTHON) -m venv $(LEROBOT_ENV)
	$(LEROBOT_ENV)/bin/pip install --quiet torch==2.9.1 torchvision==0.24.1 'torchcodec==0.8.*' lerobot==0.4.4
	command -v ffmpeg >/dev/null || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && \
		(apt-get install -y -q ffmpeg >/dev/null 2>&1 || \
		 (apt-get update -q >/dev/null 2>&1 && apt-get install -y -q ffmpeg >/dev/null 2>&1)); } || \
		echo "ffmpeg not installed: the torchcodec reader will be skipped"
	touch $@

lerobot-env: $(LEROBOT_ENV)/.installed-stamp

test-lerobot: setup lerobot-env
	SONG_LEROBOT_PYTHON=$(LEROBOT_ENV)/bin/python $(VENV)/bin/pytest -q tests/runtime/test_lerobot.py

# Detectors trained on real photos judge the avatars (tests/datasets/avatars/test_real_photo_detectors.py):
# MediaPipe 0.10.21 and OpenCV in benchmarks/people.py's own environment, built by that benchmark's installer
test-people: setup
	$(PY) -c "from benchmarks.people import ensure_detectors; ensure_detectors()"
	SONG_PEOPLE_PYTHON=build/bench-envs/people/bin/python $(VENV)/bin/pytest -q tests/datasets/avatars/test_real_photo_detectors.py

# the API reference, generated from the docstrings (a warning, e.g. a module that fails to import, fails it)
api: setup
	rm -rf build/api
	$(PY) -W error::UserWarning -m pdoc --docformat google --output-directory build/api song
	@echo "API reference: build/api/index.html"

lint: setup
	$(VENV)/bin/ruff check --fix song tests benchmarks
	$(VENV)/bin/ruff format song tests benchmarks

clean:
	rm -rf $(VENV) runs .pytest_cache build
