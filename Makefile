PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-test

.PHONY: demo test install clean

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(VENV)/.installed: $(VENV)/bin/python pyproject.toml
	$(PY) -m pip install --quiet -e .
	touch $@

# The test environment through uv (installed into the venv by pip; PyPI's): it resolves and installs the same
# versions as pip in ~7 s against pip's ~41 s on the 2-core machine, a tenth of a fresh clone's `make test`.
# pip's own find-links and constraints (pip config) are passed on; if uv fails for any reason, pip installs.
$(STAMP): $(VENV)/bin/python pyproject.toml
	$(PY) -m pip install --quiet uv && \
	  FL=$$($(PY) -m pip config get global.find-links 2>/dev/null); \
	  CO=$$($(PY) -m pip config get global.constraint 2>/dev/null); \
	  $(VENV)/bin/uv pip install --quiet --python $(PY) $${FL:+--find-links $$FL} $${CO:+--constraint $$CO} \
	    -e '.[test]' \
	  || $(PY) -m pip install --quiet -e '.[test]'
	touch $@ $(VENV)/.installed

install: $(VENV)/.installed

demo: $(VENV)/.installed
	$(VENV)/bin/servoscope demo --out demo-out

test: $(STAMP)
	# One worker per core; a file's tests stay on one worker, so its session fixtures
	# (rendered twin campaigns) are made once. Bytecode is written even where the machine sets
	# PYTHONDONTWRITEBYTECODE (this one does): else each of the suite's ~75 Python processes compiles
	# numpy's, scipy's, numba's, matplotlib's... sources again (~6 s of CPU a process, ~95 s a run).
	env -u PYTHONDONTWRITEBYTECODE $(PY) -m pytest -q -n auto --dist loadfile --no-loadscope-reorder

clean:
	rm -rf $(VENV) demo-out
