# drake-skill: the two commands of the README are `make demo` and `make test`.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
PYTHON ?= python3

.PHONY: setup demo test bench constraints clean-venv

setup: $(STAMP)

# torch first, as its own step: this machine has the CPU wheel of 2.13.0 on disk
# (elsewhere see the README's "CPU-only torch"). pyproject.toml has version ranges;
# constraints.txt pins the versions the tests passed with.
$(STAMP): pyproject.toml constraints.txt
	@bash tools/ensure_system_deps.sh
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -c constraints.txt -e '.[test]'
	@touch $(STAMP)

demo: setup
	$(VENV)/bin/drake-skill learn --skill open --force

test: setup
	$(PY) -m pytest -q -n 2 --dist loadgroup

bench: setup
	$(PY) tools/bench_station.py

# Rewrites constraints.txt from the versions installed in .venv.
constraints: setup
	$(PY) tools/write_constraints.py

clean-venv:
	rm -rf $(VENV)
