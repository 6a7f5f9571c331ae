# Developer and CI entry points. Everything runs from the project's own .venv,
# which `venv` builds from requirements.txt (PyPI only) on a fresh clone.

VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

# Python 3.11 is what Blender 4.2-5.0 and the pip `bpy` wheel use.
PYTHON311 := $(shell \
	if command -v python3.11 >/dev/null 2>&1; then echo python3.11; \
	elif python3 -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; \
	then echo python3; fi)

# The built-in basis is built once (about 80 s) and cached here for demo, bench
# and tests alike; outside make it defaults to ~/.cache/brdf_reconstruct.
export BRDF_RECONSTRUCT_CACHE ?= $(CURDIR)/.cache

.PHONY: venv test lint demo bench extension clean

# Internal: (re)install only when requirements.txt or pyproject.toml change.
venv: $(STAMP)

$(STAMP): requirements.txt pyproject.toml
	@if [ ! -x $(PY) ]; then \
		if [ -z "$(PYTHON311)" ]; then \
			echo "error: Python 3.11 is needed (python3.11, or python3 being 3.11)" >&2; \
			exit 1; \
		fi; \
		echo "creating $(VENV) with $(PYTHON311)"; \
		$(PYTHON311) -m venv $(VENV); \
	fi
	$(PY) -m pip install --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install --disable-pip-version-check -e . --no-deps
	@touch $@

# The tests run in TEST_WORKERS processes (pytest-xdist; CI has 2 cores), each test
# file in one of them (module fixtures are built once), each with one BLAS thread:
# with a BLAS thread per core each, two workers spent a quarter of their CPU time
# in the kernel (measured on 2 cores: 17 min 50 s against 13 min 0 s). The two
# built-in bases are built first (once, not by both workers), with the BLAS threads
# a single process has: their float32 sums depend on the BLAS threads (up to 2e-4
# in the basis vectors), and a basis built otherwise than the tests' numbers were
# measured on moves the Lambert's textured shape from 1.29x to 1.53x (asked: 1.5x).
TEST_WORKERS ?= 2

test: venv
	$(VENV)/bin/ruff check .
	$(PY) -c "from brdf_reconstruct.core.brdf import basis; basis.load_default(); basis.load_measured()"
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

lint: venv
	$(VENV)/bin/ruff check .

demo: venv
	$(PY) bench/demo.py

# The benchmarks, plus their dev-only extras: Mitsuba 3 for the peer comparison
# (requirements-bench.txt), whose CPU backend needs the system's libLLVM >= 17
# (Debian 12: libllvm19, installed here with apt-get when missing).
BENCH_STAMP := $(VENV)/.bench-installed

bench: venv $(BENCH_STAMP)
	$(PY) bench/run_all.py

$(BENCH_STAMP): requirements-bench.txt $(STAMP)
	@if ! ldconfig -p | grep -Eq 'libLLVM(-(1[7-9]|[2-9][0-9])\.so|\.so\.(1[7-9]|[2-9][0-9]))'; then \
		echo "installing libllvm19 (Mitsuba's CPU backend needs libLLVM >= 17)"; \
		if [ "$$(id -u)" = 0 ]; then apt-get update -qq && apt-get install -y libllvm19; \
		else sudo apt-get update -qq && sudo apt-get install -y libllvm19; fi; \
	fi
	$(PY) -m pip install --disable-pip-version-check -r requirements-bench.txt
	@touch $@

# Installable extension zips, one per platform, into dist/ (brdf_reconstruct-<version>-linux_x64.zip,
# ..._windows_x64.zip, ..._macos_arm64.zip) with scipy and pycolmap wheels for Python 3.11 and 3.13
# bundled; wheels are downloaded once into .cache/wheels. Options go in EXTENSION_ARGS, e.g.
#   make extension EXTENSION_ARGS="--platforms linux-x64 --pythons 3.11"
extension: venv
	$(PY) scripts/build_extension.py $(EXTENSION_ARGS)

# Removes the environment and caches; keeps bench/results and .cache/ (data).
clean:
	rm -rf $(VENV) *.egg-info .pytest_cache .ruff_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
