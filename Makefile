# vbl-robust: set-up, demo, tests, benchmarks.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

export YOLO_OFFLINE := 1
export YOLO_CONFIG_DIR := $(CURDIR)/.cache/ultralytics
export YOLO_VERBOSE := False
export MPLBACKEND := Agg

.PHONY: install demo test test-full bench lint clean

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/vbl-robust demo --out runs/demo

test: $(STAMP)
	$(BIN)/pytest -q -x --timeout=900 --durations=15

test-full: $(STAMP)
	$(BIN)/pytest -q --timeout=3600 --full

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py --out BENCHMARKS.md

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

clean:
	rm -rf runs .pytest_cache .cache
