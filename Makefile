# The two quick-start commands: `make demo` (the main job) and `make test` (the whole suite).
PYTHON ?= python3
STAMP := .make-installed

$(STAMP): pyproject.toml
	$(PYTHON) -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	rhbl demo

test: $(STAMP)
	$(PYTHON) -m pytest -q tests

lint: $(STAMP)
	ruff check .

.PHONY: install demo test lint
