# Parallax: `make setup` installs everything on a fresh Debian 12 machine (idempotent),
# `make test` runs the suite, `make demo` renders the demo scene.
PYTHON_SYS ?= /usr/bin/python3
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
STAMP := $(VENV)/.deps-stamp

.PHONY: setup system venv build test asan demo bench extension scenes clean

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

# Two workers (pytest-xdist), a test file each at a time: lavapipe compiles a pipeline on one
# thread, so one worker's compiles overlap the other's renders.
test: setup
	@$(PY) -m pytest -q -p no:cacheprovider -n 2 --dist loadfile

# The core built with AddressSanitizer + UndefinedBehaviorSanitizer + LeakSanitizer (into
# build-asan/), running the unit and render tiers against it: scripts/asan.sh.
asan: system venv
	@bash scripts/asan.sh $(PY)

# The demo is the Blender scene, rendered through bpy exactly as F12 would.
demo: setup
	@mkdir -p out
	@$(VENV)/bin/parallax render blender_scenes/cornell_box.blend -o out/cornell_box.exr --png out/cornell_box.png
	@echo "wrote out/cornell_box.exr and out/cornell_box.png"

# Rebuilds the .blend files from blender_scenes/build.py.
scenes: setup
	@$(PY) blender_scenes/build.py

# The installable Blender extension: the add-on plus the native core as a cp311 wheel, and
# pyoidn's wheel (the OIDN library for Blenders without one), packed from the venv's install.
BLENDER_EXT = $(wildcard $(VENV)/lib/python3.11/site-packages/bpy/*/scripts/addons_core/bl_pkg/cli/blender_ext.py)
extension: setup
	@rm -rf addon/wheels dist/parallax-*.zip && mkdir -p dist
	@$(PIP) wheel -q --no-build-isolation --no-deps -w addon/wheels .
	@$(PY) scripts/wheel_from_installed.py pyoidn addon/wheels >/dev/null
	@$(PY) $(BLENDER_EXT) build --source-dir addon --output-dir dist
	@ls dist/parallax-*.zip

bench: setup
	@$(PY) bench/throughput.py

clean:
	rm -rf build build-asan out dist addon/wheels addon/_site
