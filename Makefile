# Two entry points for a fresh machine with only Python 3.11: `make demo` and `make test`.
# Both create .venv and install the package on first use (and again when pyproject.toml changes).
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.setup-stamp

.PHONY: setup demo test test-fast lint bench bench-docs

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "make: $(PYTHON) not found; set PYTHON=/path/to/python3.11"; exit 2; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	# torch first, pinned to the CPU build, so that pip never resolves a CUDA build for it
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e ".[test]"
	# the place-matching kernels compiled once here (numba caches them beside their source), not in a first run
	$(BIN)/python -m neoslam.loop.kernels
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/neoslam run --out results/demo --overwrite

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks docs
	$(BIN)/ruff format --check src tests benchmarks docs

test: lint
	$(BIN)/pytest -q

# the inner loop: lint and every test but those marked slow (whole drives, real processes), in about a minute
test-fast: lint
	$(BIN)/pytest -q -m "not slow"

# every benchmark's quick mode (results in benchmarks/results/NAME.quick.json); `make bench-docs` puts the stored
# default-mode results (benchmarks/results/NAME.json) into the pages of docs/benchmarks/
bench: $(STAMP)
	for b in $$($(BIN)/python -c "from benchmarks.harness import benchmark_names; print(*benchmark_names())"); do \
		$(BIN)/python -m benchmarks.$$b --quick || exit 1; \
	done

bench-docs: $(STAMP)
	$(BIN)/python -m benchmarks.render
