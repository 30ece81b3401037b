# Entry points for a fresh machine. `make pipeline` and `make test` create .venv first when needed.
# lerobot 0.6.1 needs Python 3.12: we take the first 3.12 among python3.12, python3 (pyenv resolves it through
# .python-version) and pyenv's installs; override with `make PYTHON=/path/to/python3.12 ...`.
PYTHON ?= $(shell for p in python3.12 python3 $$HOME/.pyenv/versions/3.12*/bin/python3; do \
	$$p -c 'import sys; sys.exit(sys.version_info[:2] != (3, 12))' 2>/dev/null && { echo $$p; break; }; done)
VENV := .venv
BIN := $(CURDIR)/$(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: soak install pipeline test test-fast bench compare lock clean-venv

install: $(STAMP)

$(STAMP): requirements.lock pyproject.toml
	@test -n "$(PYTHON)" || { echo "error: Python 3.12 not found (lerobot 0.6.1 needs it); pass PYTHON=/path/to/python3.12" >&2; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip==26.3
	$(BIN)/python -m pip install -q -r requirements.lock
	$(BIN)/python -m pip install -q --no-deps --no-build-isolation -e .
	touch $@

# The whole default pipeline: collect -> ... as declared in dvc.yaml.
pipeline: $(STAMP)
	@$(BIN)/python tools/check_locks.py
	PATH="$(BIN):$$PATH" dvc repro

# Every tier: unit tests and smoke runs, learning thresholds (-m learning), the real pipeline end to end (-m slow).
test: $(STAMP)
	PATH="$(BIN):$$PATH" python -m pytest

# Tier 1 only: unit tests and tiny-budget smoke runs of every method (about a minute), for the edit-test loop.
test-fast: $(STAMP)
	PATH="$(BIN):$$PATH" python -m pytest -m "not slow and not learning and not soak"

# The soak: the tiny pipeline SIGKILLed at 20 seeded random moments, resumed each time, and run on a disk that
# fills, then grows (minutes; CI runs it).
soak: $(STAMP)
	PATH="$(BIN):$$PATH" python -m pytest -m soak -n 0

# The committed run beside its experiments (`dvc exp run -S KNOB=VALUE`): the changed knobs and metrics, one row
# each, within 200 columns (tools/compare.py; `make compare ARGS=--all` for every commit's experiments).
compare: $(STAMP)
	PATH="$(BIN):$$PATH" python tools/compare.py $(ARGS)

bench: $(STAMP)
	PATH="$(BIN):$$PATH" python benchmarks/env_throughput.py

lock: $(STAMP)
	$(BIN)/python -m pip freeze --exclude-editable > requirements.lock.new && mv requirements.lock.new requirements.lock

clean-venv:
	rm -rf $(VENV)
