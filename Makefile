# drake-skill: the two commands of the README are `make demo` and `make test`.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
PYTHON ?= python3

.PHONY: setup demo test bench notebooks mutation constraints clean-venv

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

# The page tests' browser (Debian's chromium and chromium-driver) is a test-only step.
test: setup
	@bash tools/ensure_system_deps.sh --test
	$(PY) -m pytest -q -n 2 --dist loadscope

bench: setup
	$(PY) tools/bench_station.py

# JupyterLab on notebooks/ (pyproject.toml's `notebooks` extra; not needed by the tests,
# which execute the notebooks with nbclient). On a remote machine: make notebooks LAB_ARGS="--no-browser --ip 127.0.0.1".
LAB_ARGS ?=
notebooks: setup
	$(PY) -m pip install -q -c constraints.txt -e '.[notebooks]'
	$(VENV)/bin/jupyter lab notebooks/ $(LAB_ARGS)

# Mutation testing (mutmut, configured in pyproject.toml [tool.mutmut]); not part of
# `make test` nor CI: hours on two cores. One mutmut run per module (MUTATE=...
# picks some: `make mutation MUTATE="drake_skill.reward.mrp drake_skill.fileio"`);
# mutmut runs each mutant against only the tests of the selection that call the
# mutated function, and resumes where it stopped. Scores: docs/mutation.md.
# mutmut forks each mutant's test run from one process: with more than one
# OpenMP or BLAS thread started before the fork, a child that first calls
# k-means or a threaded solve waits forever on a lock of the parent's pool, so
# the pools are kept to one thread (the tests do not depend on thread counts).
MUTATION_ENV = OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
MUTATE ?= drake_skill.action.quaternion drake_skill.reward.mrp drake_skill.fileio \
	drake_skill.learning.policy_search drake_skill.reward.pomrp drake_skill.perception.features \
	drake_skill.action.dmp drake_skill.perception.segmentation drake_skill.demos.format \
	drake_skill.reward.goal_model drake_skill.station.placement drake_skill.station.loggers \
	drake_skill.skills.spec drake_skill.learning.runlog drake_skill.demos.robomimic \
	drake_skill.experiments.report drake_skill.station.reflex drake_skill.station.controller
MUTMUT_CHILDREN ?= 2
mutation: setup
	$(PY) -m pip install -q -c constraints.txt -e '.[test,mutation]'
	@mkdir -p mutants
	@for m in $(MUTATE); do \
		echo "== mutmut run $$m.* (log: mutants/$$m.log)"; \
		$(MUTATION_ENV) nice -n 15 $(VENV)/bin/mutmut run --max-children $(MUTMUT_CHILDREN) "$$m.*" > mutants/$$m.log 2>&1 \
			|| { tail -n 40 mutants/$$m.log; exit 1; }; \
	done
	$(VENV)/bin/mutmut results

# Rewrites constraints.txt from the versions installed in .venv.
constraints: setup
	$(PY) tools/write_constraints.py

clean-venv:
	rm -rf $(VENV)
