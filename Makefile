# csdf: `make test` and `make demo` work on a fresh machine (they create .venv first).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: test demo bench gallery storage lint clean editor-bundle

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,plan,dask,openscad]'
	touch $(STAMP)

# the test suite runs in this many processes (pytest-xdist), each test file in one of
# them (module fixtures built once); 0 runs it in this process
TEST_WORKERS ?= 2

test: $(STAMP)
	$(PY) -m ruff check src tests examples benchmarks docs
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadfile

bench: $(STAMP)
	$(PY) benchmarks/bench_eval.py
	$(PY) benchmarks/bench_mesh.py
	@for b in render fit; do \
	  if [ -f benchmarks/bench_$$b.py ]; then $(PY) benchmarks/bench_$$b.py || exit 1; fi; \
	done

demo: $(STAMP)
	$(PY) -m csdf.demo

storage: $(STAMP)
	$(PY) docs/storage_table.py

gallery: $(STAMP)
	$(PY) docs/make_gallery.py docs/gallery.png

# the live editor's CodeMirror 6 bundle (committed; only maintainers need node and npm)
editor-bundle:
	cd editor && npm ci --no-audit --no-fund && npm run build

lint: $(STAMP)
	$(PY) -m ruff check src tests examples benchmarks docs

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info .pytest_cache .hypothesis
