# `make demo` and `make test` set everything up on a fresh machine: arapkit with every extra
# (`all`: figures, editor, Dask, tet mesher; not torch, which .ci/run adds) and the test tools.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test bench lint clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[all,test]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/arapkit demo --out demo-output

test: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/lint-imports

clean:
	rm -rf $(VENV) demo-output .pytest_cache
	# numba caches are keyed on their own file only: a kernel inlined from another
	# module (rotations into solver) keeps a stale copy until the cache is removed
	find src -name "*.nbi" -delete -o -name "*.nbc" -delete
