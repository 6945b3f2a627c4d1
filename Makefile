# Lanterna: set-up, render, test. Everything installs itself into .venv (reused while current).
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.lanterna-installed

.PHONY: render test bench clean scenes extension test-compat fuzz

# Blender versions the add-on is tested against (make test-compat): bpy 4.2 LTS and 4.5 LTS in
# their own environments, 5.0 in .venv. The Blender-facing tests (the rest need no bpy).
BPY_42 := 4.2.23
BPY_45 := 4.5.15
COMPAT_TESTS := tests/test_blender_engine.py tests/test_ui.py tests/test_export.py \
                tests/test_cli.py tests/test_ase.py tests/test_overlay.py \
                tests/test_extension.py tests/test_farm.py tests/test_settings.py \
                tests/test_portability.py

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

# One installable zip per platform in dist/, built and validated by Blender's blender_ext.py.
extension: $(STAMP)
	$(PY) tools/build_extension.py

.venv-bpy%/.lanterna-installed: pyproject.toml
	@test -x .venv-bpy$*/bin/python || $(PYTHON) -m venv .venv-bpy$*
	.venv-bpy$*/bin/python -m pip install -q --upgrade pip
	.venv-bpy$*/bin/python -m pip install -q -e '.[test]' bpy==$(BPY_$*)
	@touch $@

test-compat: $(STAMP) .venv-bpy42/.lanterna-installed .venv-bpy45/.lanterna-installed
	@for py in .venv-bpy42/bin/python .venv-bpy45/bin/python $(PY); do \
	  echo "== bpy $$($$py -c 'import importlib.metadata as m; print(m.version("bpy"))') ($$py)"; \
	  start=$$(date +%s); \
	  PYTHONPATH=tools $$py -m pytest -q -p no:cacheprovider -p pytest_bpy_exit \
	    $(COMPAT_TESTS) || exit 1; \
	  echo "== $$(( $$(date +%s) - start )) s"; \
	done

# The full fuzz run (tests/fuzz.py): 420 damaged .blend, ASE and maps inputs, a CSV and a
# table by kind and outcome; about 15 minutes on 2 cores. make test runs a quick subset.
fuzz: $(STAMP)
	@mkdir -p out
	$(PY) tests/fuzz.py --count 420 --csv out/fuzz.csv --work out/fuzz

bench: $(STAMP)
	$(VENV)/bin/lanterna bench

scenes: $(STAMP)
	@mkdir -p out
	$(VENV)/bin/lanterna scene scene1 -o out/scene1.blend
	$(VENV)/bin/lanterna scene scene2 -o out/scene2.blend

clean:
	rm -rf out dist build *.egg-info .venv-bpy42 .venv-bpy45
