# Lanterna: set-up, render, test. Everything installs itself into .venv (reused while current).
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.lanterna-installed

.PHONY: render test bench clean scenes

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[blender,test]'
	@touch $(STAMP)

render: $(STAMP)
	@mkdir -p out
	$(VENV)/bin/lanterna render -o out/scene1.exr --png out/scene1.png --report out/scene1.json

test: $(STAMP)
	$(PY) -m pytest -q

bench: $(STAMP)
	$(VENV)/bin/lanterna bench

scenes: $(STAMP)
	@mkdir -p out
	$(VENV)/bin/lanterna scene scene1 -o out/scene1.blend
	$(VENV)/bin/lanterna scene scene2 -o out/scene2.blend

clean:
	rm -rf out dist build *.egg-info
