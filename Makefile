# occtool: `make demo` runs the bundled example, `make test` the tests, `make lint` ruff and mypy,
# `make bench` the benchmark.
# Each target sets up its own virtual environment on first use (Python >= 3.10 needed).
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.occtool-installed
DEMO   ?= demo-output

.PHONY: install demo test test-slow test-all bench lint pictures clean

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
	$(BIN)/occtool plot features fixtures/office/features.csv -o $(DEMO)/fig5a-features.png
	$(BIN)/occtool plot model $(DEMO)/model.json -o $(DEMO)/fig5b-model.png --pieces
	$(BIN)/occtool plot nav $(DEMO)/nav.geojson --features fixtures/office/features.csv \
		--truth fixtures/office/truth.json -o $(DEMO)/fig5c-navigation.png
	@echo
	@echo "Demo written to $(DEMO)/:"
	@echo "  model.json inverse.json nav.geojson"
	@echo "  $(DEMO)/fig5a-features.png  $(DEMO)/fig5b-model.png  $(DEMO)/fig5c-navigation.png"

# The suite less the slow end-to-end and property checks (marked @pytest.mark.slow);
# `make test-slow` runs those, `make test-all` everything, as CI does.
test: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q -m "not slow"

test-slow: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q -m slow

test-all: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q

lint: $(STAMP)
	$(BIN)/ruff check occtool tests bench
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python bench/run.py --output bench/results.md

# Redraw docs/images/ from occtool's current outputs by the docs' own commands
# (tools/pictures.py; needs ../shared/data for the Intel, CCNY and MINES maps).
pictures: $(STAMP)
	$(BIN)/python tools/pictures.py

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache .hypothesis
