# Parallax: `make setup` installs everything on a fresh Debian 12 machine (idempotent),
# `make test` runs the suite, `make demo` renders the demo scene.
PYTHON_SYS ?= /usr/bin/python3
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
STAMP := $(VENV)/.deps-stamp

.PHONY: setup system venv build test demo bench clean

setup: system venv build

system:
	@bash scripts/setup_system.sh

$(STAMP): scripts/requirements.txt
	@test -x $(PY) || $(PYTHON_SYS) -m venv $(VENV)
	@$(PIP) install -q --upgrade pip
	@$(PIP) install -q -r scripts/requirements.txt
	@touch $(STAMP)

venv: $(STAMP)

# Incremental: scikit-build-core keeps its CMake tree under build/.
build: venv
	@$(PIP) install -q --no-build-isolation --no-deps .

test: setup
	@$(PY) -m pytest -q -p no:cacheprovider

demo: setup
	@mkdir -p out
	@$(VENV)/bin/parallax scene cornell_box -o out/cornell_box.npz --width 512 --height 512
	@$(VENV)/bin/parallax render out/cornell_box.npz -o out/cornell_box.exr --png out/cornell_box.png --spp 128 --spp-per-frame 8
	@echo "wrote out/cornell_box.exr and out/cornell_box.png"

bench: setup
	@$(PY) bench/throughput.py

clean:
	rm -rf build out
