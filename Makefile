# Fresh machine: `make demo` (set up + run the main job on the sample scenes) or `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
SONG := $(VENV)/bin/song
STAMP := $(VENV)/.installed-stamp
RUN ?= runs/demo
BENCH ?= runs/demo-bench
SCENES ?= datasets/sample_scenes

.PHONY: setup demo test lint format bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first, pinned: the local CPU wheel (an unpinned torch pulls a multi-GB CUDA build)
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[all,dev]'
	# third-party reference implementations for tests/benchmarks; their extra deps are not needed
	$(PY) -m pip install --quiet --no-deps pyrvo==0.4.3 pynavmesh==1.2.5
	touch $(STAMP)

setup: $(STAMP)

demo: setup
	$(SONG) scenes check $(SCENES)
	$(SONG) synth --scenes $(SCENES) --out $(RUN) --workers 2

test: setup
	$(VENV)/bin/ruff check song tests benchmarks
	$(VENV)/bin/ruff format --check song tests benchmarks
	$(VENV)/bin/pytest -q -m "not slow"

lint: setup
	$(VENV)/bin/ruff check --fix song tests benchmarks
	$(VENV)/bin/ruff format song tests benchmarks

clean:
	rm -rf $(VENV) runs .pytest_cache
