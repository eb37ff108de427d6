# ffstream: the two commands of the README, plus helpers.
#
#   make demo   installs what is missing, builds, runs the Cornell box end to end
#   make test   installs what is missing, runs the whole test suite
#
# Works on a fresh Debian/Ubuntu machine that has only Rust: the `deps` target installs
# Open MPI (runtime + headers), libclang (rsmpi's bindgen), gfortran (the uDALES reader
# test, tests/fortran/) and the Python packages of the .ffz reader's tests and of the
# .vtu check (meshio, tests/python/), each only if missing (python3-venv: `make test` installs the reader
# with pip into a fresh virtual environment). Uses sudo when not root.

SHELL := /bin/bash
CARGO ?= cargo
PYTHON ?= python3
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
APT_PACKAGES := libopenmpi-dev openmpi-bin libclang-dev pkg-config python3-pip python3-venv time gfortran
PY_PACKAGES := numpy scipy zstandard crc32c pytest matplotlib meshio
# Open MPI refuses root without these; harmless otherwise. --oversubscribe is passed
# by the tests and by demo-mpi (this may be a 2-core machine).
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
# Vector instructions: on an x86-64 CPU with AVX2, FMA, BMI2 and MOVBE (x86-64-v3:
# Intel Haswell / AMD Zen and later) build for them: the Bvh traversal and the far-field
# kernel then take ~15 % less CPU, with bitwise the same rows (bench/PERF.md section 7).
# With AVX-512 F, BW, CD, DQ and VL as well, build for x86-64-v4: the shadow-ray packets
# then use one 16-lane register instead of two 8-lane ones (room:900 ~10 % less CPU, the
# 8.5k room unchanged, bitwise the same rows: bench/PERF.md section 10).
# A binary built this way needs such a CPU: for a portable build set RUSTFLAGS yourself
# (e.g. `make build RUSTFLAGS=`) or use cargo directly.
CPU_FLAGS := $(shell grep -m1 '^flags' /proc/cpuinfo 2>/dev/null)
ifeq ($(origin RUSTFLAGS),undefined)
  ifeq ($(shell echo "$(CPU_FLAGS)" | tr ' ' '\n' | grep -c -x -E 'avx2|fma|bmi2|movbe|avx512f|avx512bw|avx512cd|avx512dq|avx512vl'),9)
    export RUSTFLAGS := -C target-cpu=x86-64-v4
  else ifeq ($(shell echo "$(CPU_FLAGS)" | tr ' ' '\n' | grep -c -x -E 'avx2|fma|bmi2|movbe'),4)
    export RUSTFLAGS := -C target-cpu=x86-64-v3
  endif
endif

.PHONY: demo demo-mpi test deps sys-deps py-deps rust-tools build bench bench-quick fuzz clean

demo: deps build
	./target/release/ffstream run builtin:cornell --out-dir out/cornell
	@echo "==> picture: out/cornell/image.png (radiosity table: out/cornell/radiosity.csv)"

demo-mpi: deps build
	mpirun -n 3 --oversubscribe ./target/release/ffstream run builtin:cornell --out-dir out/cornell-mpi

# The Python reader is tested as users install it: `pip install ./formats` into a fresh
# virtual environment (the dependencies formats/pyproject.toml declares, plus pytest), then
# formats/test_ffz.py against that installed module (--import-mode=importlib, FFZ_INSTALLED
# checks it) and a real computed file (the Cornell box at 300 patches, in 64 KiB chunks so
# it has several), checked against its `ffstream export` through FFZ_FILE/FFZ_MTX/FFZ_CSV.
#
# The tests run a binary built with the `test-hooks` feature (fault injection read from
# the environment, tests/README.md); then the product binary is rebuilt without it and
# checked to hold none of the hooks' variable names, and the benchmarks and the Python
# reader's tests use that product binary.
HOOK_VARS := FFSTREAM_FAIL_ROW FFSTREAM_TEST_STOP_ROW FFSTREAM_TEST_SCENE_RANK
test: deps
	$(CARGO) fmt --check
	$(CARGO) clippy --all-targets --features test-hooks --quiet -- -D warnings
	$(CARGO) clippy --quiet -- -D warnings
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --no-deps --document-private-items --quiet
	$(CARGO) check --no-default-features --all-targets --quiet
	$(CARGO) check --manifest-path fuzz/Cargo.toml --target-dir target --no-default-features --quiet
	$(CARGO) test --release --features test-hooks
	$(CARGO) build --release
	@for v in $(HOOK_VARS); do \
	  if grep -aq "$$v" target/release/ffstream; then \
	    echo "error: the product binary target/release/ffstream reads the test hook $$v"; exit 1; fi; \
	done; echo "==> the product binary holds no test hook ($(HOOK_VARS))"
	$(CARGO) bench --no-run --quiet
	$(PYTHON) bench/run.py --quick
	@tmp=$$(mktemp -d) && \
	$(PYTHON) -m venv $$tmp/venv && \
	$$tmp/venv/bin/python -m pip install -q --disable-pip-version-check ./formats pytest && \
	./target/release/ffstream compute builtin:cornell --patches 300 --chunk-kib 64 --quiet -o $$tmp/c.ffz && \
	./target/release/ffstream export $$tmp/c.ffz --matrix $$tmp/c.mtx --patches-csv $$tmp/c.csv && \
	FFZ_INSTALLED=1 FFZ_FILE=$$tmp/c.ffz FFZ_MTX=$$tmp/c.mtx FFZ_CSV=$$tmp/c.csv \
	  $$tmp/venv/bin/python -m pytest -q -p no:cacheprovider --import-mode=importlib formats/test_ffz.py; \
	status=$$?; rm -rf $$tmp; exit $$status

build:
	$(CARGO) build --release

deps: sys-deps py-deps rust-tools

# clippy and rustfmt come with rustup's default profile; add them if the toolchain
# was installed with the minimal one.
rust-tools:
	@$(CARGO) clippy --version >/dev/null 2>&1 || rustup component add clippy
	@$(CARGO) fmt --version >/dev/null 2>&1 || rustup component add rustfmt

sys-deps:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "==> installing:$$missing"; \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get update -qq && \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; \
	fi

py-deps:
	@$(PYTHON) -c "import numpy, scipy, zstandard, crc32c, pytest, matplotlib, meshio" 2>/dev/null || { \
	  echo "==> installing Python packages: $(PY_PACKAGES)"; \
	  $(PYTHON) -m pip install -q $(PY_PACKAGES) || $(PYTHON) -m pip install -q --break-system-packages $(PY_PACKAGES); }

bench: deps build
	-$(PYTHON) -m pip install -q pyviewfactor
	$(PYTHON) bench/run.py

bench-quick: deps build
	$(PYTHON) bench/run.py --quick

# Fuzzing (documented in tests/README.md): a long run of the stable-Rust mutation fuzzer,
# then libFuzzer through cargo-fuzz (needs RUSTC_BOOTSTRAP on a stable toolchain),
# seeded from the golden files and the scene corpus, FUZZ_SECONDS per target.
FUZZ_SECONDS ?= 60
fuzz:
	FFSTREAM_FUZZ_ITERS=100000 $(CARGO) test --test it stress_fuzz -- --nocapture
	command -v cargo-fuzz >/dev/null || $(CARGO) install cargo-fuzz
	mkdir -p fuzz/corpus/ffz_reader fuzz/corpus/obj_loader
	cp formats/golden/*.ffz fuzz/corpus/ffz_reader/
	cp tests/data/scenes/*.obj tests/data/bad/*.obj fuzz/corpus/obj_loader/
	RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run ffz_reader fuzz/corpus/ffz_reader -- -max_total_time=$(FUZZ_SECONDS) -max_len=4096
	RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run obj_loader fuzz/corpus/obj_loader -- -max_total_time=$(FUZZ_SECONDS) -max_len=4096

clean:
	$(CARGO) clean
	rm -rf out
