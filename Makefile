# The two commands:  make reproduce   (the paper's full reproduction)
#                    make test        (the whole test suite)
.PHONY: setup reproduce test lint bench

setup:
	@bash scripts/setup.sh

reproduce: setup
	.venv/bin/trustseek reproduce --out report

test: setup
	.venv/bin/python -m pytest -n 2 -q

# static checks: lint and formatting, types, the layer contracts of docs/architecture.md,
# and the front end's types
lint: setup
	.venv/bin/ruff check src tests benchmarks
	.venv/bin/ruff format --check src tests benchmarks
	.venv/bin/mypy
	.venv/bin/lint-imports
	cd web && npm run typecheck --silent

bench: setup
	.venv/bin/python benchmarks/run.py
