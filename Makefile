# `make demo` and `make test` each work on a fresh machine: they create .venv, install pamid
# with its dependencies (and the test extras), then run the demo or the test suite.
VENV    := .venv
VPY     := $(VENV)/bin/python
STAMP   := $(VENV)/.pamid-installed
WARM    := $(VENV)/.pamid-warm
DEMO_OUT ?= demo-out

# pamid's modules byte-compiled where they are: an editable install leaves them as source,
# and where PYTHONDONTWRITEBYTECODE is set (the project's VMs and CI) every command, test
# worker and notebook kernel compiled them again, 0.25-0.4 s of each `pamid fit`
# (benchmarks/README.md, "Byte-compiled at install"). Only changed files are compiled again.
BYTECODE := $(VPY) -m compileall -q pamid

.PHONY: install warm-up demo test bench bench-all bench-quick clean

$(STAMP): pyproject.toml
	@py=$$(sh scripts/find-python.sh) || exit 1; \
	if [ ! -x $(VPY) ]; then echo "creating $(VENV) with $$py"; "$$py" -m venv $(VENV) || exit 1; fi
	$(VPY) -m pip install --disable-pip-version-check -q -e '.[tests]'
	@$(BYTECODE)
	@touch $@

install: $(STAMP)

# Once per installation: compile the programs of `pamid fit`, `compare` and `diagnose` for
# one-muscle files of every size class up to 4096 rows into the disk cache (PAMID_CACHE_DIR, default ~/.cache/pamid), so
# that a lab's first file starts warm (README, "The first run"). Not part of `make test`,
# whose runs keep a cache of their own.
$(WARM): $(STAMP)
	@$(BYTECODE)
	@if $(VENV)/bin/pamid warm-up; then touch $@; else \
	  echo "pamid warm-up did not finish: the first file of a class compiles its programs (make demo goes on)"; fi

warm-up: $(WARM)

demo: $(WARM)
	@$(BYTECODE)
	$(VENV)/bin/pamid demo --out $(DEMO_OUT)

# Two worker processes, each taking whole test files (module fixtures are shared within a
# file): both cores busy, and no one process compiling the whole suite's programs (a single
# process crashed inside XLA late in the run, three times in one day, 2026-11-24). A worker
# that crashes ends the run at once: pytest-xdist 3.8 replaces it and then hangs under
# --dist loadfile (pytest-xdist issues 784 and 1378), which CI saw as a 90-minute timeout.
test: $(STAMP)
	@$(BYTECODE)
	$(VPY) -m pytest -q -n 2 --dist loadfile --max-worker-restart=0

bench: $(STAMP)
	$(VPY) benchmarks/fit_batch.py

bench-all: $(STAMP)
	$(VPY) benchmarks/run.py

bench-quick: $(STAMP)
	$(VPY) benchmarks/run.py --quick

clean:
	rm -rf $(VENV) $(DEMO_OUT)
