# Pitlane: two commands set up everything.
#   make run   serve the console on http://127.0.0.1:8000 (Redis, a Celery worker and Daphne included)
#   make test  lint and run the whole test suite against real Redis, Celery, Channels and Chromium
#   make test-quick  the suite without its browser, cluster, TensorFlow and slow tests: the edit loop
#   make cluster  serve the console as several machines would (PostgreSQL, Redis, S3, one web, one
#              training and two simulation machines, each with its own code and var/) on :8000
#   make device-bundle  fetch into var/device/ what the device machine's bench carries (wheels,
#              Debian's Redis) and print the command a session with a GPU runs
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: run test test-quick cluster lint format bench device-bundle lock clean help

help:
	@sed -n 's/^#   //p' $(firstword $(MAKEFILE_LIST))

run: $(VENV)/.run-installed
	@scripts/ensure-system-package.sh redis-server command -v redis-server
	$(BIN)/python manage.py runconsole

# The suite in TEST_PROCESSES processes (pytest-xdist), those sharing a session's service together
# (tests/conftest.py); TEST_PROCESSES=0 runs it in one.
TEST_PROCESSES ?= 2
PARALLEL = $(if $(filter 0,$(TEST_PROCESSES)),,-n $(TEST_PROCESSES) --dist loadgroup --no-loadscope-reorder)

test: lint
	@scripts/ensure-system-package.sh redis-server command -v redis-server
	@scripts/ensure-system-package.sh chromium command -v chromium
	@scripts/ensure-system-package.sh postgresql sh -c 'command -v initdb || ls /usr/lib/postgresql/*/bin/initdb'
	$(BIN)/python -m pytest $(PARALLEL) $(PYTEST_ARGS)

# Not the browser (Chromium), cluster (several machines), TensorFlow nor slow tests (marked: each
# takes seconds, a real worker or a training run): run `make test` before a commit; this is for
# the loop between edits.
test-quick: $(VENV)/.test-installed
	@scripts/ensure-system-package.sh redis-server command -v redis-server
	@scripts/ensure-system-package.sh postgresql sh -c 'command -v initdb || ls /usr/lib/postgresql/*/bin/initdb'
	$(BIN)/python -m pytest -m "not browser and not cluster and not tensorflow and not slow" \
		$(PARALLEL) $(PYTEST_ARGS)

cluster: $(VENV)/.test-installed
	@scripts/ensure-system-package.sh redis-server command -v redis-server
	@scripts/ensure-system-package.sh postgresql sh -c 'command -v initdb || ls /usr/lib/postgresql/*/bin/initdb'
	$(BIN)/python -m tests.cluster

lint: $(VENV)/.test-installed
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/lint-imports --no-cache
	$(BIN)/python scripts/check_sizes.py

format: $(VENV)/.test-installed
	$(BIN)/ruff check --fix .
	$(BIN)/ruff format .

bench: $(VENV)/.test-installed
	@scripts/ensure-system-package.sh redis-server command -v redis-server
	@scripts/ensure-system-package.sh postgresql sh -c 'command -v initdb || ls /usr/lib/postgresql/*/bin/initdb'
	@for b in bench/bench_*.py; do m=$$(basename $$b .py); echo "== bench.$$m"; \
		$(BIN)/python -m bench.$$m || exit 1; done

lock:
	scripts/lock.sh

device-bundle: $(VENV)/.run-installed
	PYTHON=$(BIN)/python scripts/device-bundle.sh

$(VENV)/bin/python:
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
		{ echo "Pitlane needs Python 3.11 or newer; $(PYTHON) is $$($(PYTHON) --version)." >&2; exit 1; }
	@scripts/ensure-system-package.sh python3-venv $(PYTHON) -c 'import ensurepip, venv'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# The console reads DeepRacer for Cloud's bucket with its own client's layout (pitlane_client.drfc).
$(VENV)/.run-installed: requirements/run.txt client/pyproject.toml | $(VENV)/bin/python
	$(BIN)/python -m pip install --quiet -r requirements/run.txt
	$(BIN)/python -m pip install --quiet --no-deps -e client
	@touch $@

$(VENV)/.test-installed: requirements/test.txt client/pyproject.toml | $(VENV)/bin/python
	$(BIN)/python -m pip install --quiet -r requirements/test.txt
	$(BIN)/python -m pip install --quiet --no-deps -e client
	@touch $@ $(VENV)/.run-installed

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
