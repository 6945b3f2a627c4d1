# Lanterna: set-up, render, test. Everything installs itself into .venv (reused while current).
#
# .venv is Blender 5.2 LTS: Python 3.13, bpy 5.2.3, numpy 2. The compat environments of
# `make test-compat` are the other Blenders a user may have, each with the Python it ships:
# 4.2 LTS, 4.5 LTS and 5.0 on Python 3.11 (numpy 1.26), 5.3 on Python 3.13.
#
# Interpreters: PYTHON313 / PYTHON311 name them; otherwise the first that answers of
# python3.X on the PATH (a pyenv shim answers only when PYENV_VERSION names it) and
# $(pyenv root)/versions/3.X.*/bin/python3.X.
find_python = $(shell for c in python$(1) $$(pyenv root 2>/dev/null)/versions/$(1).*/bin/python$(1) \
                $$HOME/.pyenv/versions/$(1).*/bin/python$(1) /usr/local/bin/python$(1) \
                /usr/bin/python$(1); do \
                "$$c" -c 'import sys; assert "%d.%d" % sys.version_info[:2] == "$(1)"' \
                >/dev/null 2>&1 && { command -v "$$c"; break; }; done)
ifndef PYTHON313
PYTHON313 := $(call find_python,3.13)
endif
ifndef PYTHON311
PYTHON311 := $(call find_python,3.11)
endif
PYTHON ?= $(PYTHON313)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.lanterna-installed

.PHONY: render test test-parity bench clean scenes extension test-compat fuzz mutation

# Blender versions the add-on is tested against besides .venv's 5.2.3 (make test-compat), each
# in its own environment .venv-bpyXY with the Python that Blender ships; and the
# Blender-facing tests (the rest need no bpy).
COMPAT := 42 45 50 53
BPY_42 := 4.2.23
BPY_45 := 4.5.15
BPY_50 := 5.0.1
BPY_53 := 5.3.0
PYVER_42 := 3.11
PYVER_45 := 3.11
PYVER_50 := 3.11
PYVER_53 := 3.13
PYTHON_3.11 = $(PYTHON311)
PYTHON_3.13 = $(PYTHON313)
COMPAT_TESTS := tests/test_blender_engine.py tests/test_ui.py tests/test_export.py \
                tests/test_cli.py tests/test_ase.py tests/test_overlay.py \
                tests/test_extension.py tests/test_farm.py tests/test_settings.py \
                tests/test_portability.py tests/test_node_bake.py

# $(call need_python,INTERPRETER,3.X): stop with a message when that Python was not found.
need_python = @test -n "$(1)" || { echo "make: Python $(2) not found (looked for python$(2) on the \
PATH and in pyenv's versions folder); install it (e.g. pyenv install $(2)) or name it: \
make PYTHON$(subst .,,$(2))=/path/to/python$(2)" >&2; exit 1; }

# $(call fresh_venv,DIR,INTERPRETER): DIR as a venv of that interpreter's Python version (an
# older .venv of Python 3.11 is made anew).
fresh_venv = @v=$$($(2) -c 'import sys; print("%d.%d" % sys.version_info[:2])') && \
	  { $(1)/bin/python -c "import sys; assert '%d.%d' % sys.version_info[:2] == '$$v'" 2>/dev/null \
	    || { rm -rf $(1) && echo "creating $(1) (Python $$v: $(2))" && $(2) -m venv $(1); }; }

$(STAMP): pyproject.toml
	$(call need_python,$(PYTHON),3.13)
	$(call fresh_venv,$(VENV),$(PYTHON))
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[blender,test]'
	@touch $(STAMP)

render: $(STAMP)
	@mkdir -p out
	$(VENV)/bin/lanterna render -o out/scene1.exr --png out/scene1.png --report out/scene1.json

test: $(STAMP)
	$(PY) -m pytest -q -m "not parity"

# The whole-render comparisons with Cycles, seed scenes and inline ones (about 9 minutes); CI runs them.
test-parity: $(STAMP)
	$(PY) -m pytest -q -m parity --durations=15

# One installable zip per platform in dist/, built and validated by Blender's blender_ext.py.
extension: $(STAMP)
	$(PY) tools/build_extension.py

.venv-bpy%/.lanterna-installed: pyproject.toml
	$(call need_python,$(PYTHON_$(PYVER_$*)),$(PYVER_$*))
	$(call fresh_venv,.venv-bpy$*,$(PYTHON_$(PYVER_$*)))
	.venv-bpy$*/bin/python -m pip install -q --upgrade pip
	.venv-bpy$*/bin/python -m pip install -q -e '.[test]' bpy==$(BPY_$*)
	@touch $@

test-compat: $(STAMP) $(foreach v,$(COMPAT),.venv-bpy$(v)/.lanterna-installed)
	@for py in $(foreach v,$(COMPAT),.venv-bpy$(v)/bin/python); do \
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

# Mutation testing of the core modules (issue 19 item 4; mutation/README.md): hours for every
# mutant on two cores, so not part of `make test`. MUTATION_ARGS: e.g. photons direct.
MUTATION_VENV := .venv-mut
$(MUTATION_VENV)/.installed: pyproject.toml
	$(call need_python,$(PYTHON311),3.11)
	$(PYTHON311) -m venv $(MUTATION_VENV)
	$(MUTATION_VENV)/bin/pip install -q -e . pytest==9.2.0 hypothesis==6.170.15 mutmut==3.8.1
	touch $@

mutation: $(MUTATION_VENV)/.installed
	tools/mutation.sh --check
	tools/mutation.sh $(MUTATION_ARGS)

bench: $(STAMP)
	$(VENV)/bin/lanterna bench

scenes: $(STAMP)
	@mkdir -p out
	$(VENV)/bin/lanterna scene scene1 -o out/scene1.blend
	$(VENV)/bin/lanterna scene scene2 -o out/scene2.blend

clean:
	rm -rf out dist build *.egg-info $(foreach v,$(COMPAT),.venv-bpy$(v))
