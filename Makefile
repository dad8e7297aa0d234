# The two commands of the README:  `make demo` (the main job) and `make test` (the tests).
# Both do all the set-up first (scripts/setup.sh: apt GL libraries, .venv, pinned pip packages).
SHELL := /bin/bash
VENV := .venv/bin
OUT ?= out/demo

.PHONY: setup demo test test-slow bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(VENV)/tryon body info default:female
	$(VENV)/tryon maps default:female --out $(OUT)/maps
	$(VENV)/tryon render default:female --out $(OUT)/default_female.png
	$(VENV)/tryon drape --body default:female --garment skirt --size M --out $(OUT)/skirt
	@echo "demo: pictures in $(OUT)/"

test: setup
	$(VENV)/python -m pytest -m "not slow" -q

test-slow: setup
	$(VENV)/python -m pytest -m slow -q

bench: setup
	$(VENV)/python scripts/bench_maps.py

clean:
	rm -rf out .pytest_cache
