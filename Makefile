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
	$(BIN)/ruff check src tests benchmarks blender
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks blender
	$(BIN)/lint-imports

# The Blender extension (docs/blender.md): one zip per platform in dist/, each with arapkit and
# its dependencies as wheels for Blender's Python 3.11 (from PyPI; needs Python 3.11+ with
# pip, not the venv). `make blender-addon BLENDER_PLATFORMS=linux-x64` builds one.
BLENDER_PLATFORMS ?= linux-x64 windows-x64 macos-arm64 macos-x64
.PHONY: blender-addon
blender-addon:
	$(PYTHON) blender/build.py $(addprefix --platform ,$(BLENDER_PLATFORMS)) --out dist

clean:
	rm -rf $(VENV) demo-output .pytest_cache
	# numba caches are keyed on their own file only: a kernel inlined from another
	# module (rotations into solver) keeps a stale copy until the cache is removed
	find src -name "*.nbi" -delete -o -name "*.nbc" -delete
