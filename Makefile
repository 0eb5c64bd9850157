# Two entry points that work from a fresh clone: `make demo` and `make test`.
# Both create .venv and install the project (with dev extras) on first use, then reuse it.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-slow bench docs install clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/fricenv demo --out runs/demo

# The tests run on two worker processes (pytest-xdist); the tests that start Ray share one worker (xdist_group
# "ray"), so that no two Ray instances start side by side.
TEST_WORKERS := -n 2 --dist loadgroup

test: $(STAMP)
	$(BIN)/python -m pytest -q $(TEST_WORKERS)

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow $(TEST_WORKERS)

bench: $(STAMP)
	$(BIN)/fricenv bench --json runs/bench.json

docs: $(STAMP)
	$(BIN)/mkdocs build --strict --site-dir site

clean:
	rm -rf $(VENV) runs site .pytest_cache
