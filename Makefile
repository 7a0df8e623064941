# Quick start targets: `make run` (main job on a bundled map) and `make test` (whole suite).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup run paper test docs maps clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test,docs]'
	touch $(STAMP)

setup: $(STAMP)

run: $(STAMP)
	$(BIN)/cold-eval --map maps/junction.xodr --out out/cold-eval

test: $(STAMP)
	$(BIN)/python -m pytest -q; status=$$?; [ $$status -eq 5 ] && echo 'pytest: no tests collected' && status=0; exit $$status

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

paper: $(STAMP)
	$(BIN)/cold-eval --paper --out out/paper

maps: $(STAMP)
	$(BIN)/python tools/make_maps.py

clean:
	rm -rf $(VENV) out site .pytest_cache .hypothesis
