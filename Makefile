# Two commands do all the set-up on a fresh machine:
#   make run    the main job (results and pictures in results/)
#   make test   the whole test suite, serial and MPI
# Both create .venv with a Python >= 3.12 if it is missing.

VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# Extras: the DOLFINx wheel and the lens scenes' ipctk unless told otherwise
# (EXTRAS=test,iol for a conda DOLFINx).
EXTRAS ?= dolfinx,test,iol
# Without the wheel the venv must see the DOLFINx its interpreter already has (conda, Docker)
VENV_FLAGS ?= $(if $(findstring dolfinx,$(EXTRAS)),,--system-site-packages)
OUT    ?= results
# The main job: the scleral-buckling operation (issue #5).
MAIN   ?= scleral-buckling

.PHONY: run test bench bench-q2p1 bench-mpi bench-sweep venv clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	@set -e; \
	if [ ! -x $(PY) ]; then \
	  py=$$(sh scripts/find_python.sh) || exit 1; \
	  echo "creating $(VENV) with $$py"; \
	  "$$py" -m venv $(VENV_FLAGS) $(VENV); \
	fi; \
	$(PY) -m pip install --quiet --upgrade pip; \
	$(PY) -m pip install --quiet -e ".[$(EXTRAS)]"; \
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/eyemech run $(MAIN) --out $(OUT)

# The suite runs in one pytest process (TEST_GROUPS: the file patterns of each process;
# `make test TEST_GROUPS=tests/test_cli.py` runs one file). A process that keeps MPI
# communicators runs out of MPICH's 2,048 and then aborts or crashes (docs/parallel.md,
# "Long processes"): a test module that keeps more than a few fails (tests/conftest.py).
# TEST_LOG records each test as it starts (with the free communicators then), the free
# communicators and memory after each module, and Python's traceback on a fatal signal;
# its end is printed when a process fails.
TEST_GROUPS ?= tests
TEST_LOG    ?= $(CURDIR)/test-process.log

test: $(STAMP)
	@rm -f $(TEST_LOG); status=0; for group in $(TEST_GROUPS); do \
	  EYEMECH_TEST_LOG=$(TEST_LOG) PATH="$(CURDIR)/$(VENV)/bin:$$PATH" \
	    $(PY) -m pytest -ra --timeout=1800 $(PYTEST_ARGS) $$group || status=$$?; \
	done; \
	if [ $$status -ne 0 ]; then echo "--- end of $(TEST_LOG)"; tail -n 60 $(TEST_LOG); fi; \
	exit $$status

# A sweep of 1,000 cases in one 2-rank process (each case on both ranks) of a scene that runs in well
# under a second (the clamped strip's vibration, one time step): MPI communicators free
# and resident memory before and after, a row appended to docs/bench/sweep-lifetime.md
# (docs/parallel.md, "Long processes").
bench-sweep: $(STAMP)
	rm -rf $(OUT)/sweep-lifetime
	$(VENV)/bin/mpiexec -n 2 $(PY) -m eyemech.scripts.sweep_lifetime cantilever-vibration \
	  --cases 1000 --vary amplitude=0.005:0.015 --set divisions=2 --set periods=0.125 \
	  --set steps_per_period=8 --out $(OUT)/sweep-lifetime --record docs/bench/sweep-lifetime.md

# Performance of the main job's whole operation (IOP, buckling and suturing vented, settling):
# on the default mesh on 1 rank, and at the paper's resolution on 2 ranks with the defaults
# and with Newton directions by FGMRES on a kept factorisation (docs/scleral_buckling.md,
# "Krylov on a kept factorisation, with the NaN cut").
KRYLOV = --set linear_reuse=krylov --set krylov_max_it=30 --set krylov_rtol=1e-6
bench: $(STAMP)
	$(VENV)/bin/eyemech bench scleral-buckling --set resolution=default --out docs/bench
	$(VENV)/bin/mpiexec -n 2 $(VENV)/bin/eyemech bench scleral-buckling --out docs/bench
	$(VENV)/bin/mpiexec -n 2 $(VENV)/bin/eyemech bench scleral-buckling $(KRYLOV) --out docs/bench

# Q2P1 on the coarse eye, 1 rank: on the paper's operation its axial-length change is 8 %
# below the reference, about as far as the paper-resolution Q1P0 eye is above it, at 184
# factorisations and 360 s under load (docs/scleral_buckling.md, "Q2P1 and Q1P0 at equal
# accuracy of the axial-length change"); kept out of `bench` for its time.
bench-q2p1: $(STAMP)
	$(VENV)/bin/eyemech bench scleral-buckling --set element=Q2P1 --set resolution=coarse --out docs/bench

# Every scene at its defaults on 1, 2 and 3 ranks: wall time and the largest relative
# difference from the serial quantities (docs/parallel.md, "Every scene on 1, 2 and 3
# ranks"); about an hour on the loaded 2-core VM.
bench-mpi: $(STAMP)
	nice -n 10 $(PY) scripts/bench_mpi.py --out docs/bench

clean:
	rm -rf $(VENV) results .pytest_cache test-process.log
