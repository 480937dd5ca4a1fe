# Convenience targets; the README's two commands do not need make.
PY ?= .venv/bin/python

.PHONY: bench bench-dem bench-pbm test lint

bench: bench-dem bench-pbm

bench-dem:
	$(PY) benchmarks/bench_dem.py

bench-pbm:
	$(PY) benchmarks/bench_pbm.py

test:
	$(PY) -m pytest -q

lint:
	$(PY) -m snakemake --lint --configfile config/test.yaml
