# mocapedit: `make demo` and `make test` set up everything they need on a fresh Debian machine.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
CPP_BUILD := build/cpp
DEMO_OUT := build/demo

.PHONY: all deps build cpp test test-cpp test-py demo bench schema schema-check stages stubs clean

all: build

deps: $(VENV)/.installed

$(VENV)/.installed: requirements-dev.txt pyproject.toml
	@tools/system-deps.sh
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements-dev.txt
	@touch $@

# The Python package, installed editable: Python sources run from python/, the compiled
# solver and the schema plugin are built by CMake through scikit-build-core.
build: deps
	$(PY) -m pip install -q --no-build-isolation --no-deps -e .

# The solver library and its C++ tests, built on their own (no Python, no USD).
cpp: deps
	cmake -S . -B $(CPP_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOCAPEDIT_BUILD_TESTS=ON
	cmake --build $(CPP_BUILD)

test-cpp: cpp
	ctest --test-dir $(CPP_BUILD) --output-on-failure

test-py: build
	$(PY) -m pytest

test: test-cpp test-py

demo: build
	@bash tools/demo.sh $(DEMO_OUT)

# BENCH_ARGS=--large adds the largest sizes (30,000 agents); BENCH_ARGS="--only scale" runs one module.
bench: build
	$(PY) bench/run.py --out bench/results/bench.json $(BENCH_ARGS)

# Regenerate plugin/ from schema/schema.usda (commit both).
schema: deps
	$(PY) schema/generate.py

schema-check: deps
	$(PY) schema/generate.py --check

# Regenerate python/mocapedit/_solver.pyi from the built extension (commit it).
stubs: build
	$(PY) tools/solver_stubs.py

stages: build
	$(PY) example_stages/make_stages.py

clean:
	rm -rf build $(VENV) python/mocapedit/*.so
