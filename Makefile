# Two commands do all set-up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test bench family golden install clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q "setuptools>=68" wheel
	$(PY) -m pip install -q --no-build-isolation -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) examples/demo.py --out demo-output

# glibc hands arrays over 32 MB back to the kernel at each free, and the next one faults in fresh
# zeroed pages: the scenes' and chains' large temporaries spent a third of their time there
TEST_MALLOC := MALLOC_MMAP_THRESHOLD_=4294967296 MALLOC_TRIM_THRESHOLD_=4294967296

test: $(STAMP)
	$(TEST_MALLOC) $(PY) -m pytest -q -n 2 --dist loadgroup

bench: $(STAMP)
	$(PY) -m pip install -q --no-build-isolation -e ".[bench]"
	$(PY) benchmarks/run.py

# the power-line chain over the variant family (34 variants x SEEDS; 340 scenes take ~35 min on 2 cores)
SEEDS ?= 1-10
family: $(STAMP)
	$(PY) -m pip install -q --no-build-isolation -e ".[bench]"
	$(PY) benchmarks/powerline_family.py --seeds $(SEEDS)

# the power-line chain's golden outputs (#76): identical before and after a restructuring
golden: $(STAMP)
	$(PY) benchmarks/powerlines_golden.py check

clean:
	rm -rf $(VENV) demo-output .pytest_cache build *.egg-info
