# Two commands from a fresh clone: `make demo` and `make test`.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.deps-stamp
SO_STAMP := $(VENV)/.core-stamp
RUST_SRC := $(shell find rust -name '*.rs' -o -name Cargo.toml) Cargo.toml pyproject.toml

PYTEST := $(PY) -m pytest -q

# The tests start the CLI, the stand-in worker and Ray in hundreds of subprocesses: with
# PYTHONDONTWRITEBYTECODE set (some shells and CI images set it), each one compiles the
# package again (a tenth of a second apiece, a fifth of the fast layer).
unexport PYTHONDONTWRITEBYTECODE

.PHONY: venv develop demo test test-fast test-quick test-rust test-py test-packaging fuzz lint typecheck fmt schemas stub docs bench bench-gpu clean

venv: $(SO_STAMP)

# Dependencies in one resolver pass from the lock (numpy < 2 for bpy; DESIGN §1).
$(STAMP): requirements.lock
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements.lock
	touch $@

# The native module and the package, editable, with the `blurset` entry point.
$(SO_STAMP): $(STAMP) $(RUST_SRC)
	VIRTUAL_ENV=$(abspath $(VENV)) $(VENV)/bin/maturin develop --release -q
	touch $@

develop: $(SO_STAMP)

demo: venv
	$(VENV)/bin/blurset build --demo --out demo_out

# Every test (Rust, and Python with real Blender renders, COLMAP and Ray) but the
# release-wheel build, which has its own target; CI runs both.
test: test-rust test-py

# The fast layer: Rust and the Python tests that render nothing, spread over the cores
# (pytest-xdist; a file's tests stay on one worker, so its fixtures are made once):
# about 3 minutes on 2 cores. Tests that render run one at a time (Blender takes
# every core).
PYTEST_WORKERS ?= auto
test-fast: test-rust venv
	$(PYTEST) -n $(PYTEST_WORKERS) --dist loadfile -m "not blender and not slow and not packaging and not rebuild" tests

# --release: the dependencies maturin compiled for the extension module are reused.
test-rust:
	cargo test --release -p blurset-core --quiet

# Every Python test but the long end-to-end builds (marked slow) and packaging: real
# renders included, for checking a change to the render path before the full run.
test-quick: test-rust venv
	$(PYTEST) -m "not slow and not packaging and not rebuild" tests

test-py: venv
	$(PYTEST) -m "not packaging" tests

# Coverage-guided fuzzing of the readers of untrusted files (EXR, the JSON records,
# poses_bounds.npy; rust/fuzz), each for FUZZ_SECONDS: CI runs it after `make test`.
# libFuzzer needs nightly flags: RUSTC_BOOTSTRAP lets the stable toolchain take them.
FUZZ_SECONDS ?= 20
FUZZ_TARGETS := exr exr_memory records poses_bounds
fuzz:
	command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --locked
	RUSTC_BOOTSTRAP=1 cargo fuzz build --fuzz-dir rust/fuzz
	for t in $(FUZZ_TARGETS); do \
	  RUSTC_BOOTSTRAP=1 cargo fuzz run --fuzz-dir rust/fuzz $$t -- \
	    -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 || exit 1; \
	done

test-packaging: venv
	$(PYTEST) -m packaging tests

lint: venv
	cargo fmt --all -- --check
	cargo clippy --workspace --all-targets -- -D warnings
	$(VENV)/bin/ruff check python tests blender_scripts bench docs scripts
	$(VENV)/bin/ruff format --check python tests blender_scripts bench docs scripts
	$(PY) scripts/check_lengths.py
	$(PY) -m mypy.stubtest blurset._core --allowlist stubtest_allowlist.txt
	$(MAKE) typecheck

# mypy on python/blurset, bench, scripts and docs/gen ([tool.mypy] in pyproject.toml): zero errors.
typecheck: venv
	$(PY) -m mypy

fmt:
	cargo fmt --all
	$(VENV)/bin/ruff format python tests blender_scripts bench docs scripts
	$(VENV)/bin/ruff check --fix python tests blender_scripts bench docs scripts

# The JSON Schema of every record blurset writes, from the core's serde types (a test
# fails when schemas/ differs from them).
schemas: venv
	$(PY) -c "from blurset.services import outputs; outputs.write_schemas('schemas')"
	$(PY) -c "from blurset.services import stubgen; stubgen.write()"

# The typed option properties of _core.pyi, from the core's option declarations (a test
# fails when the stub differs from them).
stub: venv
	$(PY) -c "from blurset.services import options; options.write_stub('python/blurset/_core.pyi'); options.write_stub('python/blurset/_core.pyi', 'NoiseConfig')"

# The docs site into site/: the pages generated from the parsers, schemas/ and
# bench/results.json (docs/gen/), the checks mkdocs cannot make, then a strict build
# (a warning or a broken link fails it; no --quiet: it hides warnings from --strict).
docs: venv
	$(PY) docs/gen/cli.py
	$(PY) docs/gen/formats.py
	$(PY) docs/gen/bench.py
	$(PY) docs/gen/check.py
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

bench: venv
	$(PY) bench/run.py

# Rendering benchmarks on the best GPU Cycles reports (refused without one):
# bench/results_gpu.json. `bench/run.py --device cpu` runs the same on the CPU.
bench-gpu: venv
	$(PY) bench/run.py --device gpu

clean:
	rm -rf target $(VENV) demo_out site
