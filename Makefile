# One-command entry points for a fresh machine. Every target creates .venv on first use.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
export OMP_NUM_THREADS ?= 1
export OPENBLAS_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.PHONY: setup demo test lint bench clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip >/dev/null
	$(PY) -m pip install -e ".[gui,test]"
	touch $@

setup: $(VENV)/.installed

demo: setup
	$(PY) -m rig workflow --out demo-output

test: setup
	QT_QPA_PLATFORM=offscreen $(PY) -m pytest -q -n auto --dist worksteal
	$(PY) -m ruff check .

lint: setup
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

bench: setup
	$(PY) -m benchmarks mhb

clean:
	rm -rf $(VENV) demo-output .pytest_cache
