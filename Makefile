# ktcs-bench: every set-up step lives behind these targets, so a fresh clone needs only
#   make lab     (the main job)        and        make test     (the test suite)
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup lab test lint bench clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml .ci/system-deps
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test,dev]'
	bash .ci/system-deps
	touch $@

# The main job: the shipped reference lab (stations 18, 20, 22) -- every device its own process,
# Type I over paced ptys, Type II over TCP, taps in every link. Ctrl-C stops it.
lab: setup
	$(BIN)/ktcs-bench lab up

# The tests hold the line on lint too: ruff check, ruff format --check and strict mypy (`lint`)
# run first, and a finding fails `make test` -- and so CI -- before pytest starts.
test: setup lint
	$(BIN)/python -m pytest -q

lint: setup
	$(BIN)/ruff check ktcs_bench tests benchmarks
	$(BIN)/ruff format --check ktcs_bench tests benchmarks
	$(BIN)/mypy

bench: setup
	$(BIN)/python benchmarks/codec.py
	$(BIN)/python benchmarks/decode.py
	$(BIN)/python benchmarks/links.py
	$(BIN)/python benchmarks/links_type2.py
	$(BIN)/python benchmarks/lab.py
	$(BIN)/python benchmarks/atp.py
	$(BIN)/python benchmarks/scale.py
	$(BIN)/python benchmarks/virtual_lab.py
	$(BIN)/python benchmarks/console_flood.py
	$(BIN)/python benchmarks/verify.py --generated 20
	$(BIN)/python benchmarks/procedures_pytest.py

clean:
	rm -rf $(VENV) build dist *.egg-info .pytest_cache .mypy_cache .ruff_cache .hypothesis
