# Two-command quick start: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= demo_out

.PHONY: demo test install docs bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	# numba compiles labtool's loops once into its cache (beside the sources), here rather than in
	# the first command of make demo or make test
	$(BIN)/labtool warmup
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/labtool demo -o $(OUT)

# -n auto: one pytest worker a core (pytest-xdist); the suite runs in half the time on 2 cores
test: $(STAMP)
	$(BIN)/python -m pytest -q -n auto

# the documentation site: docs/_build/html/index.html; every warning is an error, and the examples
# of docs/examples/ run through the API on the simulated stand
DOCS_STAMP := $(VENV)/.docs-installed
$(DOCS_STAMP): pyproject.toml $(STAMP)
	$(BIN)/pip install -q -e '.[docs]'
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	MPLBACKEND=Agg $(BIN)/sphinx-build -W --keep-going -q -b html docs docs/_build/html
	@echo "docs: docs/_build/html/index.html"

bench: $(STAMP)
	@$(BIN)/python -c "import numbalsoda" 2>/dev/null || $(BIN)/pip install -q -e '.[bench]' || \
	  echo "bench: numbalsoda could not be built (it needs gfortran and cmake: apt-get install -y gfortran cmake); its peers are skipped"
	$(BIN)/python benchmarks/run_all.py
	$(BIN)/python benchmarks/peers_bench.py
	$(BIN)/python benchmarks/whole_call_bound.py
	$(BIN)/python benchmarks/bench_doe.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache docs/_build docs/auto_examples docs/sg_execution_times.rst
