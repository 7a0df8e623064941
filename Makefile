# Quick start targets: `make run` (main job on a bundled map) and `make test` (whole suite).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup run test bench maps clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

setup: $(STAMP)

run: $(STAMP)
	$(BIN)/cold-maps info maps/junction.xodr
	$(BIN)/cold-maps export maps/junction.xodr --step 0.1 --format csv -o out/junction-borders.csv

test: $(STAMP)
	$(BIN)/python -m pytest -q; status=$$?; [ $$status -eq 5 ] && echo 'pytest: no tests collected' && status=0; exit $$status

maps: $(STAMP)
	$(BIN)/python tools/make_maps.py

clean:
	rm -rf $(VENV) out .pytest_cache
