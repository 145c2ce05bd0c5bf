# Two commands do all set-up on a fresh machine (Python >= 3.10 with venv):
#   make demo   create .venv, install robogest with what the demo needs (the video and plot extras), speak a
#               sentence on the simulated humanoid
#               -> out/demo.mp4 (video with the speech audio), out/demo.npz (command trajectory), out/demo.png
#   make test   create .venv with everything (the dev extras include all others) and run the test suite (what CI runs)
# While developing: make test-fast   the same without the end-to-end tests marked slow (under 3 minutes on 2 cores)
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
DEMO_TEXT ?= Hello! I am a small robot, and I move my arms when I speak. Do you see? ... Now I rest for a moment. ... Maybe you think this is not a big deal. But I think it is wonderful!
# Headless rendering through EGL (Mesa in software, or the GPU driver).
export MUJOCO_GL ?= egl

.PHONY: demo test test-fast install install-dev lint typecheck bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -q -e .
	touch $@

$(VENV)/.installed-demo: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -q -e '.[video,plot]'
	touch $@ $(VENV)/.installed

$(VENV)/.installed-dev: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -q -e '.[dev]'
	touch $@ $(VENV)/.installed $(VENV)/.installed-demo

install: $(VENV)/.installed
install-dev: $(VENV)/.installed-dev

demo: $(VENV)/.installed-demo
	$(BIN)/robogest speak "$(DEMO_TEXT)" --save out/demo.npz --video out/demo.mp4 --plot out/demo.png

test: $(VENV)/.installed-dev
	$(BIN)/python -m pytest

test-fast: $(VENV)/.installed-dev
	$(BIN)/python -m pytest -m "not slow"

lint: $(VENV)/.installed-dev
	$(BIN)/ruff check . && $(BIN)/ruff format --check . && $(BIN)/mypy

typecheck: $(VENV)/.installed-dev
	$(BIN)/mypy

bench: $(VENV)/.installed
	$(BIN)/python benchmarks/run.py

clean:
	rm -rf out .pytest_cache .ruff_cache
