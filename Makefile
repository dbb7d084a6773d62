# shaketable: the README's two commands are `make demo` and `make test`.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup demo test test-slow bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	@command -v $(PY) >/dev/null 2>&1 || { echo "error: $(PY) not found; install Python 3.11 or run 'make PY=python3 ...'"; exit 2; }
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: setup
	$(BIN)/shaketable run elcentro_20t --out out/demo --rrd out/demo/elcentro_20t.rrd

# The README's test command, and CI's: every test not marked slow. The slow physics
# checks (`@pytest.mark.slow`: minutes each, the replay-path and CGS calibration cases,
# the papers' long programmes) run with `make test-slow`; together they no longer fit
# the suite's 20 minutes on 2 cores. With two workers the suite took 15:42 on the 2-core
# machine, the real-record suite and replay-only cases back in it (922 passed).
# JOBS: pytest-xdist workers, one per core by default (`make test JOBS=0` runs them in
# this process). Whole files go to a worker (--dist loadfile), so a module's fixture is built
# once; each process keeps one BLAS thread (sim/__init__.py).
JOBS ?= auto
test: setup
	$(BIN)/ruff check sim mjcf hydraulics tests bench
	$(BIN)/ruff format --check sim mjcf hydraulics tests bench
	$(BIN)/python -m pytest -q -m "not slow" -n $(JOBS) --dist loadfile

test-slow: setup
	$(BIN)/python -m pytest -q -m slow -n $(JOBS) --dist loadfile

bench: setup
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) out build *.egg-info
