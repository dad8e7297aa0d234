# The two commands of the README:  `make run` (the main job: the service) and `make test` (the tests).
# Both do all the set-up first (scripts/setup.sh: apt GL libraries, .venv, pinned pip packages).
SHELL := /bin/bash
VENV := .venv/bin
OUT ?= out/demo

PORT ?= 8000

.PHONY: setup run demo test test-unit test-slow fuzz fuzz-atheris bench bench-peer clean clean-kernels

setup:
	@bash scripts/setup.sh

run: setup
	@echo "tryon: open http://localhost:$(PORT)/ (API docs: /docs; data in $${TRYON_DATA:-data}/)"
	$(VENV)/python -m uvicorn --factory app.main:create_app --host 0.0.0.0 --port $(PORT)

demo: setup
	$(VENV)/tryon body info default:female
	$(VENV)/tryon maps default:female --out $(OUT)/maps
	$(VENV)/tryon render default:female --out $(OUT)/default_female.png
	$(VENV)/tryon drape --body default:female --garment skirt --size M --out $(OUT)/skirt
	@echo "demo: pictures in $(OUT)/"

# Tests run in parallel processes (pytest-xdist: one per core, at most 4); `-n 0` in PYTEST_ARGS runs them in one.
PYTEST_ARGS ?= -n auto --maxprocesses 4

test: setup
	$(VENV)/python -m pytest -m "not slow" -q $(PYTEST_ARGS)

# the unit tier: no dressing, walking, service or browser; one process, under a minute
test-unit: setup
	$(VENV)/python -m pytest -m "not slow and not integration" -q -n 0

test-slow: setup
	$(VENV)/python -m pytest -m slow -q $(PYTEST_ARGS)

# The long fuzzing run: 10,000 malformed inputs per parser (tests/fuzz/run.py; failing inputs in out/fuzz/).
FUZZ_INPUTS ?= 10000
fuzz: setup
	$(VENV)/python -m tests.fuzz.run --inputs $(FUZZ_INPUTS) --out out/fuzz

# Coverage-guided (atheris), one parser: make fuzz-atheris TARGET=glb_anim SECONDS=600
TARGET ?= obj
SECONDS ?= 300
fuzz-atheris: setup
	mkdir -p out/fuzz && cd out/fuzz && PYTHONPATH=$(CURDIR) $(CURDIR)/$(VENV)/python -m tests.fuzz.atheris_run $(TARGET) -max_total_time=$(SECONDS)

bench: setup
	$(VENV)/tryon bench --out out/bench

# The peer in `tryon bench` (Newton's cloth solver on Warp, CPU): ~400 MB, so not in the default install.
bench-peer: setup
	$(VENV)/python -m pip install -q --disable-pip-version-check "warp-lang==1.19.0" "newton==1.8.0"

clean:
	rm -rf out .pytest_cache

# numba's compiled kernels (cached beside the sources, in __pycache__, keyed by the text of each
# kernel file and the kernel files it imports: engine/jit.py): delete them to compile afresh.
clean-kernels:
	find engine -path '*/__pycache__/*' \( -name '*.nbi' -o -name '*.nbc' \) -delete
