# Convenience targets; the README's two commands do not need make.
PY ?= .venv/bin/python

.PHONY: bench bench-quick bench-dem bench-pbm bench-pbm-accuracy bench-ranks test lint

bench: bench-dem bench-pbm bench-pbm-accuracy bench-ranks

# every benchmark's --quick mode (a few minutes; the smoke test of tests/test_benchmarks.py)
bench-quick:
	$(PY) -m pytest -q tests/test_benchmarks.py

bench-dem:
	$(PY) benchmarks/bench_dem.py point

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
