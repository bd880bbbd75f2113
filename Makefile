# The commands people type. `make demo` and `make test` each set up everything they
# need on a fresh Debian 12 machine: system packages, a virtual environment in .venv,
# and an incremental build in build/.

PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
DATA ?= ../shared/data
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
PYTAG := $(shell $(PYTHON) -c "import sys; print(f'cp{sys.version_info[0]}{sys.version_info[1]}')")
BUILD_DIR = $(firstword $(wildcard build/$(PYTAG)-*))

APT_PACKAGES := build-essential pkg-config libpcl-dev libeigen3-dev libfftw3-dev \
	liborocos-kdl-dev libkdl-parser-dev liburdfdom-dev libgtest-dev \
	clang-14 libclang-rt-14-dev
# clang-14 and libclang-rt-14-dev (Debian 12's Clang and its sanitizer and libFuzzer
# runtimes) build the fuzz targets of `make fuzz`.
PIP_BUILD := "scikit-build-core>=0.10" "pybind11>=3" cmake ninja
PIP_RUNTIME := "numpy>=1.24" "pytest>=8" "hypothesis>=6" "pybullet>=3.2" "matplotlib>=3.7" ruff mypy
PIP_BENCH := "open3d>=0.19" "small_gicp>=1.0" "kiss-matcher>=1.0"  # the `bench` extra of pyproject.toml

.PHONY: all demo test test-cpp test-python test-sanitize test-tsan fuzz install system-deps venv bench bench-peers bench-servo-peers bench-servo-sets bench-views experiments \
	format lint clean

all: install

# The main job: the paper's robot experiment (servo the simulated iiwa's wrist camera back
# to its reference view), then a model alignment on the real milk-carton scan.
demo: install
	$(VENV)/bin/spectral-vs servo-sim --out results/servo
	$(VENV)/bin/spectral-vs demo --data $(DATA) --output results/demo

test: install test-cpp test-python

test-cpp:
	$(VENV)/bin/ctest --test-dir $(BUILD_DIR) --output-on-failure

test-python:
	SPECTRAL_VS_DATA=$(DATA) $(PY) -m pytest

# The C++ library and its full GoogleTest suite under AddressSanitizer (leak detection
# on) and UndefinedBehaviorSanitizer, in build/asan (CMakePresets.json, preset "asan";
# no Python module). About 6 minutes of build and 1 minute of tests on 2 cores.
test-sanitize: system-deps venv
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" cmake --preset asan
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" cmake --build --preset asan
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" SPECTRAL_VS_DATA=$(abspath $(DATA)) ctest --preset asan

# The C++ tests of threads (parallel alignments, one ModelAligner shared by two threads,
# the same result with one and two threads, FFTW's and the SO(3) search's threads) under
# ThreadSanitizer, in build/tsan (preset "tsan"; third-party suppressions only). About 5
# minutes of build and 3 of tests on 2 cores (docs/reliability.md).
test-tsan: system-deps venv
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" cmake --preset tsan
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" cmake --build --preset tsan
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" SPECTRAL_VS_DATA=$(abspath $(DATA)) ctest --preset tsan

# libFuzzer (Clang 14, ASan + UBSan) on the PCD and PLY readers, the URDF-to-chain path
# of Kinematics, align() and cloud_from_depth, FUZZ_SECONDS each, in build/fuzz (preset "fuzz"); corpora
# seeded from $(DATA) and small generated files, kept between runs. Any crash, sanitizer
# report, uncaught exception or hang fails it (fuzz/run_fuzzers.sh, docs/reliability.md).
FUZZ_SECONDS ?= 60
fuzz: system-deps venv
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" cmake --preset fuzz
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" cmake --build --preset fuzz
	fuzz/run_fuzzers.sh build/fuzz $(FUZZ_SECONDS) $(abspath $(DATA))
	# The Python harness over whole integer ranges (tests/python/test_properties.py), longer.
	SPECTRAL_VS_HARNESS_EXAMPLES=2000 SPECTRAL_VS_DATA=$(DATA) $(PY) -m pytest -q -p no:cacheprovider tests/python/test_properties.py -k whole_range
	SPECTRAL_VS_HARNESS_EXAMPLES=2000 SPECTRAL_VS_DATA=$(DATA) $(PY) -m pytest -q -p no:cacheprovider tests/python/test_api_harness.py

# Installs only the Debian packages that are missing, so a second run is instant.
system-deps:
	@missing=$$(for p in $(APT_PACKAGES); do \
		dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || echo $$p; done); \
	if [ -n "$$missing" ]; then \
		echo "Installing Debian packages:" $$missing; \
		$(SUDO) apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $$missing; \
	fi

$(VENV)/.stamp: Makefile
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(PIP_BUILD) $(PIP_RUNTIME)
	touch $@

venv: $(VENV)/.stamp

# The build directory build/<wheel tag> is kept between runs: a rebuild with nothing
# changed only re-links nothing and re-packs the wheel.
install: system-deps venv
	$(PY) -m pip install -q --no-build-isolation --no-deps \
		-Ccmake.define.SPECTRAL_VS_BUILD_TESTS=ON -Ccmake.define.SPECTRAL_VS_BUILD_BENCHMARKS=ON .

bench: install
	$(PY) benchmarks/translation_benchmark.py --build-dir $(BUILD_DIR)
	$(PY) benchmarks/rotation_benchmark.py
	$(PY) benchmarks/alignment_benchmark.py

# The paper's experiments C-1 to C-3 and the real scans (about 15 minutes on 2 cores):
# benchmarks/results/experiments.json, docs/figures/experiments_*.png, docs/experiments.md.
experiments: install
	SPECTRAL_VS_DATA=$(DATA) $(PY) benchmarks/experiments.py

# Ours against Open3D and small_gicp (the `bench` extra) on the same cases (about 25 minutes
# on 2 cores): benchmarks/results/peers.json, docs/figures/peers_*.png, docs/benchmarks.md.
bench-peers: install
	$(PY) -m pip install -q $(PIP_BENCH)
	SPECTRAL_VS_DATA=$(DATA) $(PY) benchmarks/peers_benchmark.py

# The spectral servo against the dense depth-map servo and ICP / FPFH position-based
# servoing on the same simulated start poses of both arms (several hours on 2 cores):
# benchmarks/results/servo_peers/, servo_peers.json, docs/figures/servo_domain.png and
# servo_step_times.png, docs/benchmarks.md and docs/servoing.md.
bench-servo-peers: install
	$(PY) -m pip install -q $(PIP_BENCH)
	$(PY) benchmarks/servo_peers.py --starts 10

# The servo's eight start sets of docs/servoing.md (20 starts each, one thread; about 15
# minutes on 2 cores): benchmarks/results/servo_sets/ and the table there.
bench-servo-sets: install
	$(PY) benchmarks/servo_sets.py

# Scene-to-scene registration on view pairs of the real scans and of the simulation: ours
# (when the library has `align_views`) against Open3D ICP, FPFH + RANSAC + ICP and
# KISS-Matcher + ICP (about 6 minutes on 2 cores): benchmarks/results/view_pairs.json,
# docs/benchmarks.md.
bench-views: install
	$(PY) -m pip install -q $(PIP_BENCH)
	OMP_NUM_THREADS=1 SPECTRAL_VS_DATA=$(DATA) $(PY) benchmarks/view_pairs_benchmark.py

format:
	$(VENV)/bin/ruff format python tests benchmarks
	find cpp bindings tests/cpp examples fuzz -name '*.[ch]pp' | xargs clang-format -i

lint:
	$(VENV)/bin/ruff check python tests benchmarks
	$(VENV)/bin/ruff format --check python tests benchmarks
	$(PY) -m mypy

clean:
	rm -rf build
