# vbl-robust: set-up, demo, tests, documentation, wheel, benchmarks.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

export YOLO_OFFLINE := 1
export YOLO_CONFIG_DIR := $(CURDIR)/.cache/ultralytics
export YOLO_VERBOSE := False
export MPLBACKEND := Agg
export NO_MKDOCS_2_WARNING := 1

.PHONY: install demo test test-full docs wheel bench lint clean

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

# The documentation site (mkdocs.yml) into build/site/, strict: a broken link, a missing page or a docstring
# mkdocstrings cannot read fails the build. `make test` builds it too (tests/test_docs.py).
docs: $(STAMP)
	$(BIN)/mkdocs build --strict

# The wheel (shipped models, model card, CLI entry point) into dist/; tests/test_wheel.py checks its contents.
wheel: $(STAMP)
	rm -rf build/lib  # setuptools never cleans it: a deleted module would ride along
	$(BIN)/python -m build --wheel --no-isolation --outdir dist

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py --out BENCHMARKS.md

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

clean:
	rm -rf runs .pytest_cache .cache build dist
