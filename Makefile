# The two commands:  make reproduce   (the paper's full reproduction)
#                    make test        (the whole test suite)
.PHONY: setup reproduce test lint bench

setup:
	@bash scripts/setup.sh

reproduce: setup
	.venv/bin/trustseek reproduce --out report

# every test, with the static checks (make lint) beside them in a process of their own (mypy on a
# clean clone takes a minute of one core, which the tests' waits leave free), their output printed
# after the tests'; either failing fails the target.  One BLAS thread per test worker, so that the
# two workers do not oversubscribe the cores (the compiled code is built by setup: nothing compiles
# while the tests run)
test: setup
	@log=$$(mktemp); $(MAKE) --no-print-directory lint > "$$log" 2>&1 & lint=$$!; \
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 .venv/bin/python -m pytest -n 2 --dist worksteal -q; tests=$$?; \
	wait $$lint; checks=$$?; cat "$$log"; rm -f "$$log"; \
	if [ $$checks -ne 0 ]; then echo "test: the static checks failed (above)"; fi; \
	[ $$tests -eq 0 ] && [ $$checks -eq 0 ]

# static checks: lint and formatting, types, the layer contracts of docs/architecture.md,
# and the front end's types
lint: setup
	@echo "lint: ruff, mypy, import contracts, front-end types"
	.venv/bin/ruff check src tests benchmarks scripts setup.py
	.venv/bin/ruff format --check src tests benchmarks scripts setup.py
	.venv/bin/mypy
	.venv/bin/lint-imports
	cd web && npm run typecheck --silent

bench: setup
	.venv/bin/python benchmarks/run.py
