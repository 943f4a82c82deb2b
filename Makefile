# Quick start: `make demo` and `make test`. Both set up .venv first (system
# libraries too, when missing and we may install them). `make test-quick`
# leaves out the tests marked slow (pytest -m "not slow"); `make test` runs all.
# `make docs` rewrites docs/commands.md from the argparse definitions (a test
# fails when it is stale: run it after changing an option).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: demo test test-quick lint docs setup system-deps bench bench-check clean

demo: $(STAMP)
	$(VENV)/bin/facepuppet demo --out demo-out --force

# One pytest worker process per core (pytest-xdist); each takes the next test as it finishes one.
test: $(STAMP)
	$(PY) -m pytest -q -n auto --dist worksteal

test-quick: $(STAMP)
	$(PY) -m pytest -q -n auto --dist worksteal -m "not slow"

lint: $(STAMP)
	$(VENV)/bin/ruff check .

docs: $(STAMP)
	$(PY) -m facepuppet.runtime.cli.reference docs/commands.md

setup: $(STAMP)

system-deps:
	bash .ci/system-deps

$(STAMP): pyproject.toml package.json package-lock.json .ci/system-deps
	bash .ci/system-deps
	# The tests' reference implementations (glTF-Validator, three-vrm, playwright-core), pinned by the lock file.
	command -v npm >/dev/null 2>&1 && npm ci --no-audit --no-fund --silent || echo "facepuppet: npm missing or failed; the tests against the glTF-Validator, three-vrm and Chromium will skip"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[offline,video,panel,batch,web,vcam,test]'
	touch $(STAMP)

# Benchmarks on the real ICT head from ../shared/data (imported first).
DATA := ../shared/data
ICT := $(DATA)/ict-facekit
export FACEPUPPET_DATA ?= $(abspath $(DATA))
bench: $(STAMP)
	mkdir -p bench-out
	test -f bench-out/ict.npz || $(VENV)/bin/facepuppet import-rig $(ICT)/generic_neutral_mesh.obj $(ICT) -o bench-out/ict.npz
	$(VENV)/bin/facepuppet bench render -c bench-out/ict.npz --json bench-out/render.json

# The working tree against BASE (default the previous commit) in one sitting, A/B by turns: bench render
# (--frames 60 at 1280x720) and bench latency (--seconds 5; 640x480, VMC at 120 Hz), ROUNDS runs of each on
# each side, the medians compared (ratio per figure, > 20 % worse flagged). Each side imports the ICT head with
# its own code. About 3 minutes on 2 cores; its files in .bench/ (ignored by git). docs/benchmarks.md.
BASE ?= HEAD~1
ROUNDS ?= 3
bench-check: $(STAMP)
	$(PY) -m facepuppet.runtime.bench.bench_check --base $(BASE) --rounds $(ROUNDS) --render-frames 60 \
		--render-size 1280x720 --latency-seconds 5 --out .bench

clean:
	rm -rf $(VENV) node_modules build dist *.egg-info demo-out bench-out .bench
