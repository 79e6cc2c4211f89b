# Two-command quick start: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= demo_out

.PHONY: demo test install bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/labtool demo -o $(OUT)

# -n auto: one pytest worker a core (pytest-xdist); the suite runs in half the time on 2 cores
test: $(STAMP)
	$(BIN)/python -m pytest -q -n auto

bench: $(STAMP)
	@$(BIN)/python -c "import numbalsoda" 2>/dev/null || $(BIN)/pip install -q -e '.[bench]' || \
	  echo "bench: numbalsoda could not be built (it needs gfortran and cmake: apt-get install -y gfortran cmake); its peers are skipped"
	$(BIN)/python benchmarks/run_all.py
	$(BIN)/python benchmarks/peers_bench.py
	$(BIN)/python benchmarks/whole_call_bound.py
	$(BIN)/python benchmarks/bench_doe.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
