# One-command entry points for a fresh machine. Every target creates .venv on first use.
#   make setup     the virtual environment with the GUI, test and Dask extras
#   make gui-deps  (as root, Debian/Ubuntu) the system packages the GUI needs: Qt's X11 (xcb)
#                  plugin libraries, and Xvfb, xdotool, x11-utils and imagemagick, with which the
#                  tests start the real GUI on a virtual display and take a screenshot
#   make check     the fast tier: lint, format and type checks (beside them the balance's numba
#                  code is compiled into numba's cache, make warm) and the tests not marked slow
#                  or hardware, on every core (under 2 minutes on a 2-core machine)
#   make test      the same checks and the whole test suite (as CI runs it)
#   make demo | lint | warm | bench | clean
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
export OMP_NUM_THREADS ?= 1
export OPENBLAS_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.PHONY: setup gui-deps demo check test lint warm bench clean

# Qt's offscreen platform (the tests), its X11 platform (libqxcb.so: rig/gui/qt_check.py names
# the same libraries when one is missing), a virtual X server and the tools to drive it.
GUI_DEBS := libegl1 libgl1 libfontconfig1 libdbus-1-3 libxkbcommon0 libxkbcommon-x11-0 \
	libx11-6 libx11-xcb1 libxcb1 libxcb-cursor0 libxcb-icccm4 libxcb-image0 libxcb-keysyms1 \
	libxcb-randr0 libxcb-render0 libxcb-render-util0 libxcb-shape0 libxcb-shm0 libxcb-sync1 \
	libxcb-util1 libxcb-xfixes0 libxcb-xkb1 fonts-dejavu-core \
	xvfb xauth xdotool x11-utils imagemagick

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[gui,test,dask]"
	touch $@

setup: $(VENV)/.installed

gui-deps:
	@missing=""; for p in $(GUI_DEBS); do \
		dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -z "$$missing" ]; then echo "the GUI's system packages are installed"; else \
		echo "installing:$$missing"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
			--no-install-recommends $$missing >/dev/null; \
	fi

demo: setup
	$(PY) -m rig workflow --out demo-output

PYTEST := QT_QPA_PLATFORM=offscreen $(PY) -m pytest -q -n auto --dist worksteal

lint: setup
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) -m mypy

# the balance's numba code compiled into numba's cache (python -m analysis.mhb.warmup) beside
# the linters: the test processes then load it instead of each compiling it at the same time
warm: setup
	$(PY) -m analysis.mhb.warmup

check: setup
	$(MAKE) --no-print-directory -j2 lint warm
	$(PYTEST) -m "not slow and not hardware"

test: setup
	$(MAKE) --no-print-directory -j2 lint warm
	$(PYTEST) --durations=15

bench: setup
	$(PY) -m benchmarks mhb

clean:
	rm -rf $(VENV) demo-output .pytest_cache .mypy_cache
