# Two commands do all the set-up on a fresh machine (Python 3.11, pip, make):
#   make run    - a calibration on the simulated bench
#   make test   - the test suite
#   make docs   - the documentation site into site/ (warnings are errors)
#   make warm   - compile the simulators' kernels into the cache (install does it too)
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test lint bench clean install docs warm

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# --no-compile: pip would byte-compile every installed module (most never imported, e.g. the
	# libraries' own tests); Python compiles the ones a command imports, once, on first import
	$(BIN)/python -m pip install --quiet --no-compile -e '.[dev]'
	$(BIN)/python -m simulators.warm  # compile the kernels now, so a first run finds them cached
	touch $(STAMP)

warm: $(STAMP)
	$(BIN)/python -m simulators.warm

install: $(STAMP)

run: $(STAMP)
	$(BIN)/gyrobench run hrg-damping --station sim-hrg --report

# the suite in $(TEST_WORKERS) processes (pytest-xdist), then the tests marked `serial` (bounded in
# wall-clock time or paced in real time) alone, so no other test's load can stretch their clocks
TEST_WORKERS ?= 3
test: $(STAMP)
	QT_QPA_PLATFORM=offscreen $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist worksteal -m "not serial"
	QT_QPA_PLATFORM=offscreen $(BIN)/python -m pytest -q -m serial
	$(BIN)/ruff check .

lint: $(STAMP)
	$(BIN)/ruff check .

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

bench: $(STAMP)
	$(BIN)/python benchmarks/sim_speed.py

clean:
	rm -rf $(VENV) runs .pytest_cache site .kernel_cache
