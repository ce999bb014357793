# osnerf: `make demo` and `make test` each set everything up on a fresh Debian 12 machine.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
LLVM_LIB := /usr/lib/x86_64-linux-gnu/libLLVM-19.so
STAMP := $(VENV)/.installed
PYTEST_ARGS ?=

.PHONY: demo test bench setup llvm lint clean

setup: $(STAMP) llvm

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	# torch first: the pinned CPU wheel; any other spec pulls gigabytes of CUDA.
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e '.[dev]'
	@touch $(STAMP)

# sionna-rt and Mitsuba need LLVM >= 16 as a shared library (LLVM 14/15 crash).
llvm:
	@if [ -e $(LLVM_LIB) ] || [ -n "$$DRJIT_LIBLLVM_PATH" ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing libllvm19 (needed by sionna-rt / Mitsuba on CPU)"; \
		apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q libllvm19; \
	else \
		echo "ray tracing needs LLVM 19: run 'sudo apt-get install libllvm19' (Debian 12), then re-run make" >&2; \
		exit 1; \
	fi

demo: setup
	$(VENV)/bin/osnerf demo

test: setup
	$(VENV)/bin/pytest -q $(PYTEST_ARGS)

bench: setup
	$(PY) -m benchmarks

lint: setup
	$(VENV)/bin/ruff check phy semcodec renderer hil osnerf tests benchmarks

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
