# occtool: `make demo` runs the bundled example, `make test` the tests, `make bench` the benchmark.
# Each target sets up its own virtual environment on first use (Python >= 3.10 needed).
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.occtool-installed
DEMO   ?= demo-output

.PHONY: install demo test bench lint clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[all,dev]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	@mkdir -p $(DEMO)
	$(BIN)/occtool fit fixtures/office/features.csv -o $(DEMO)/model.json
	$(BIN)/occtool info $(DEMO)/model.json
	$(BIN)/occtool invert $(DEMO)/model.json -o $(DEMO)/inverse.json
	$(BIN)/occtool extract $(DEMO)/model.json -o $(DEMO)/nav.geojson --slices
	$(BIN)/occtool evaluate $(DEMO)/nav.geojson fixtures/office/truth.json
	@echo "demo output written to $(DEMO)/: model.json inverse.json nav.geojson"

test: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q

bench: $(STAMP)
	$(BIN)/python bench/run.py --output bench/results.md

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache .hypothesis
