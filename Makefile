# Two commands do everything on a fresh Debian 12 machine (see README.md):
#   make demo   set up, then run the pipeline headless on the bundled sample into out/
#   make test   set up, then run the whole test suite (core, headless FreeCAD, GUI under Xvfb)
#   make test-fast  the unit tests that are not marked slow (the inner loop)
PYTHON := .venv/bin/python

.PHONY: setup demo test test-fast benchmark clean

setup:
	@bash scripts/setup.sh

demo: setup
	@$(PYTHON) examples/demo.py out

test: setup
	@$(PYTHON) -m pytest tests -q

test-fast: setup
	@$(PYTHON) -m pytest tests -q -m "unit and not slow"

benchmark: setup
	@$(PYTHON) benchmarks/run.py

clean:
	rm -rf out .pytest_cache tests/gui/output
