# brdfgan — `make demo` and `make test` work on a fresh clone: both build .venv first.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.setup-complete
TORCH_PIN := torch==2.13.0
# Mitsuba's LLVM variant needs LLVM >= 17 (Debian's default 14-16 abort, docs/conventions.md#mitsuba-variant).
LIBLLVM := $(firstword $(wildcard /usr/lib/x86_64-linux-gnu/libLLVM-19.so /usr/lib/aarch64-linux-gnu/libLLVM-19.so))
ifneq ($(LIBLLVM),)
export DRJIT_LIBLLVM_PATH ?= $(LIBLLVM)
endif

.PHONY: setup test test-research test-fast test-slow faults demo demo-renderer lint format bench data ood clean

setup: $(STAMP)

$(STAMP): pyproject.toml Makefile scripts/install_gltf_validator.sh scripts/install_chromium.sh scripts/vendor_three.sh
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || { echo "error: $(PYTHON) must be Python >= 3.11" >&2; exit 1; }
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet $(TORCH_PIN)
	$(PY) -m pip install --quiet -e '.[dev]'
	@if [ "$$(id -u)" = 0 ] && ! ls /usr/lib/*/libLLVM-19.so* >/dev/null 2>&1 && command -v apt-get >/dev/null; then \
		echo "installing Debian's libllvm19 for Mitsuba's LLVM variant"; \
		export DEBIAN_FRONTEND=noninteractive; \
		apt-get install -y -qq libllvm19 >/dev/null 2>&1 || { apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq libllvm19 >/dev/null 2>&1; } \
		|| echo "warning: libllvm19 could not be installed; Mitsuba falls back to the slower scalar_rgb variant" >&2; \
	fi
	@# The Khronos glTF validator (npm) for the .glb export test; optional, never fails setup.
	@bash scripts/install_gltf_validator.sh
	@# Debian's Chromium (headless) for the browser tests and screenshots; optional, never fails setup.
	@bash scripts/install_chromium.sh
	@# three.js (npm, pinned) bundled into src/brdfgan/viewer/three.bundle.js for OUT/<name>/index.html;
	@# optional, never fails setup.
	@bash scripts/vendor_three.sh
	@touch $(STAMP)

# The product's tests (tests/, the package's doctests), then the research tier (research/tests: the
# lab's one-offs and the modules only they use, docs in research/README.md), each its own session.
test: setup
	$(PY) -m pytest -q
	$(PY) -m pytest -q research/tests

test-research: setup
	$(PY) -m pytest -q research/tests

# The unit tier, ~1.5 min on 2 cores: no subprocesses (train/evaluate/generate, the CLI, DDP workers,
# Chromium), Lightning Trainer, Hydra composition or Mitsuba; those are marked integration.
test-fast: setup
	$(PY) -m pytest -q -m 'not slow and not integration'

test-slow: setup
	$(PY) -m pytest -q -m slow

# Fault injection against the real commands (kills, full disks, corrupt files): a table of
# scenario | expected | result; minutes. Disk-full rows mount small tmpfs folders (root).
faults: setup
	$(PY) -m faults

# The artist's path on the photos the package ships (held-out procedural materials): tileable
# textures with height and ambient occlusion, material.glb, material.json, preview.png, a
# turntable preview.gif and the viewer page index.html per photo.
demo: setup
	$(VENV)/bin/brdfgan predict src/brdfgan/samples --out outputs/demo --animate --tileable
	@echo "results: outputs/demo/<photo>/ (open index.html in a browser, or material.glb in any glTF viewer)"

# The foundation demo: our renderer against Mitsuba 3 on the same maps.
demo-renderer: setup
	$(PY) -m brdfgan.renderer_demo

LINTED := src tests research scripts benchmarks faults *.py

lint: setup
	$(PY) -m ruff check $(LINTED)
	$(PY) -m ruff format --check $(LINTED)
	$(PY) -m mypy

format: setup
	$(PY) -m ruff format $(LINTED)
	$(PY) -m ruff check --fix $(LINTED)

bench: setup
	$(PY) -m benchmarks.bench_renderer
	$(PY) -m benchmarks.bench_train
	$(PY) -m benchmarks.bench_capture
	$(PY) -m benchmarks.bench_generate
	$(PY) -m benchmarks.bench_refine
	$(PY) -m benchmarks.bench_datamodule
	$(PY) -m benchmarks.bench_rendered
	$(PY) -m benchmarks.bench_sensor
	$(PY) -m benchmarks.bench_evaluate
	$(PY) -m benchmarks.bench_predict
	$(PY) -m benchmarks.bench_preview
	$(PY) -m benchmarks.bench_tiling
	$(PY) -m benchmarks.bench_views
	$(PY) -m benchmarks.bench_pair

data: setup
	$(PY) generate.py

# The out-of-distribution benchmark: real scanned materials (../shared/ood/ambientcg, or
# BRDFGAN_OOD_DIR) photographed like the test split into data/ood, and the same 7 sets at close
# range (crops spanning 20-30 deg, phone-processed photos) into data/ood_close (each generated when
# absent); the shipped weights and the three trivial references evaluated on both:
# OOD_OUT/{standard,close}/metrics.{md,json}.
OOD_OUT ?= outputs/ood
REFERENCES := src/brdfgan/weights/references
OOD_MODELS := 'ckpt={shipped: src/brdfgan/weights/default.safetensors, mean_maps: $(REFERENCES)/mean_maps.safetensors, photo_basecolor: $(REFERENCES)/photo_basecolor.safetensors, de_lit: $(REFERENCES)/de_lit.safetensors}'
# The flash + no-flash rows (the benchmark's photos have their no-flash twins): the shipped model
# and the de-lit reference on the flash-only photo, and predict --no-flash's pair fit.
OOD_PAIR_ROWS := 'pair_rows={flash_only: [shipped, de_lit], fit: [shipped]}'
ood: setup
	$(PY) generate.py dataset_spec=ood progress=false contact_sheet=8
	$(PY) generate.py dataset_spec=ood_close progress=false contact_sheet=8
	$(PY) evaluate.py data=ood hydra.run.dir=$(OOD_OUT)/standard $(OOD_MODELS) $(OOD_PAIR_ROWS)
	$(PY) evaluate.py data=ood_close hydra.run.dir=$(OOD_OUT)/close $(OOD_MODELS) $(OOD_PAIR_ROWS)
	@echo "shipped = $$($(PY) -c 'import json; print(json.load(open("src/brdfgan/weights/default.json"))["model_id"])')"
	@echo "standard (FOV 40-75 deg, predict's intake): $(OOD_OUT)/standard/metrics.md"
	@cat $(OOD_OUT)/standard/metrics.md
	@echo "close range (FOV 20-30 deg, phone-processed): $(OOD_OUT)/close/metrics.md"
	@cat $(OOD_OUT)/close/metrics.md

clean:
	rm -rf $(VENV) .node outputs multirun .pytest_cache .ruff_cache src/*.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
