# Convenience targets; the README's two commands do not need make.
PY ?= .venv/bin/python

.PHONY: bench bench-dem bench-pbm bench-pbm-accuracy bench-ranks test lint

bench: bench-dem bench-pbm bench-pbm-accuracy bench-ranks

bench-dem:
	$(PY) benchmarks/bench_dem.py

bench-ranks:
	$(PY) benchmarks/bench_ranks.py

bench-pbm:
	$(PY) benchmarks/bench_pbm.py

bench-pbm-accuracy:
	$(PY) benchmarks/bench_pbm_accuracy.py

test:
	$(PY) -m pytest -q

lint:
	$(PY) -m snakemake --lint --configfile config/test.yaml
