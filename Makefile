# Thin wrapper: dependencies, build, run the default scene, tests, benchmarks.
#   make run    install deps if missing, build, run the nonlocal chute on 2 ranks, plot it
#               and render its particles (scripts/render.py, when ParaView is installed);
#               it replaces its own previous output in $(RUN_DIR) (-output_overwrite)
#   make test   install deps if missing, build, run every test (unit, MPI on 1-3 ranks, CLI)
BUILD   ?= build
JOBS    ?= 2
NP      ?= 2
PYTHON  ?= $(shell [ -x /usr/bin/python3 ] && echo /usr/bin/python3 || echo python3)
ROOTFLAG := $(shell [ "$$(id -u)" = 0 ] && echo --allow-run-as-root)
# Yield when waiting: on a machine shared with other work a busy-polling rank waiting for a
# descheduled partner made the 2-rank chute step 2.7x slower (docs/performance.md).
MPIEXEC ?= mpiexec --oversubscribe --mca mpi_yield_when_idle 1 $(ROOTFLAG)
RUN_DIR ?= output/chute_nonlocal

.PHONY: all deps build run test test-sanitize bench clean

all: build

deps:
	@scripts/install-deps.sh

build: deps
	@cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release > /dev/null
	@cmake --build $(BUILD) -j$(JOBS)

run: build
	$(MPIEXEC) -n $(NP) $(BUILD)/granmpm -options_file examples/chute_nonlocal.opts -output_dir $(RUN_DIR) -output_overwrite
	$(PYTHON) scripts/plot_chute.py $(RUN_DIR)/profile.csv $(RUN_DIR)/profile.png
	@if command -v pvbatch > /dev/null; then $(PYTHON) scripts/render.py $(RUN_DIR) -o $(RUN_DIR)/particles.png --field velocity:Y; \
	else echo "make run: no ParaView (pvbatch), so no picture $(RUN_DIR)/particles.png (apt-get install paraview python3-paraview xvfb)"; fi
	@echo "Output: $(RUN_DIR)/ (particles.xmf and grid.xmf open in ParaView; profile.csv; plots $(RUN_DIR)/profile.png, particles.png)"

test: build
	cd $(BUILD) && ctest --output-on-failure

# Address + undefined-behaviour sanitizer build of the unit and MPI tests (CI runs it too).
# Leak checking is off: MPI and PETSc keep allocations alive until exit by design.
test-sanitize: deps
	@cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=Debug -DGRANMPM_SANITIZE=ON > /dev/null
	@cmake --build build-asan -j$(JOBS) --target unit_tests mpi_tests granmpm
	cd build-asan && ASAN_OPTIONS=detect_leaks=0 ctest --output-on-failure -R "unit|mpi_np"

bench: build
	$(PYTHON) bench/run_all.py

clean:
	rm -rf $(BUILD)
