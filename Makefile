# The two set-up commands: `make demo` and `make test`.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin

.PHONY: demo test check install install-test install-baselines clean

$(BIN)/python:
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "make: $(PYTHON) not found (set PYTHON=...)" >&2; exit 2; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	@touch $@

# the viewer's browser test runs Debian's chromium package (no downloaded browser build); the cluster
# tests run Dask's scheduler and workers (the cluster extra)
$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test,cluster]'
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi; \
	  $$SUDO apt-get update -qq && $$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; }
	@touch $@ $(VENV)/.installed

install: $(VENV)/.installed
install-test: $(VENV)/.installed-test

# optional: Open3D, for `tactrec bench baselines` (about 480 MB)
install-baselines: | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[baselines]'

demo: install
	$(BIN)/tactrec demo

# a module's tests on one worker, so that its shared fixtures (models, tables, calibrations) are built once
test: install-test
	$(BIN)/python -m pytest -n 2 --dist loadscope -q

# the edit loop: the layout, the docs, the surfaces, the estimate, the steps, the field, the paper's
# registration, recognition rates, the curves' meeting and the service (about 2 minutes on 2 cores);
# `make test` is the whole suite, as CI runs it
CHECK := test_imports test_docs test_surfaces test_normal_scales test_solver test_mesh test_report test_field \
         test_serve test_registration test_traces test_recognition test_estimation
check: install-test
	$(BIN)/python -m pytest -n 2 -q $(CHECK:%=tests/%.py)

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info .pytest_cache tactrec-demo.png tactrec-demo.html bench-out
