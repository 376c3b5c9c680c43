# The commands of the README (deploy/install-deps.sh, run first, installs make itself):
#   make run    installs what is missing, builds the programs (Release), starts tesserad on 127.0.0.1:8080 (./data)
#   make test   installs what is missing, builds everything, runs the whole test suite (the fuzz targets' replay and
#               fixed-seed tests included, from $(FUZZ_BUILD))
# Other targets: build (the programs), asan (sanitizer build + tests), fuzz (each libFuzzer target for
# FUZZ_SECONDS), bench, image (podman), deb (cpack, in build-deb), format, clean.

BUILD ?= build
ASAN_BUILD ?= build-asan
DEB_BUILD ?= build-deb
# The libFuzzer targets of tests/fuzz, built by clang in a directory of their own (the main build is g++'s).
FUZZ_BUILD ?= build-fuzz
# `make fuzz`: seconds per target, which targets (every folder of tests/fuzz/corpus), where the finds go.
FUZZ_SECONDS ?= 300
FUZZ_TARGETS ?= $(notdir $(wildcard tests/fuzz/corpus/*))
FUZZ_FINDINGS ?= $(FUZZ_BUILD)/findings
# The instruction set of $(BUILD), whose binaries run where they are built: this machine's (5-7 % faster renders than
# the x86-64 baseline; images are bit-identical either way). `make deb` and `make image` build for any x86-64.
ARCH ?= native
JOBS ?= $(shell nproc)
DATA_DIR ?= $(CURDIR)/data
PORT ?= 8080
# What running needs: the daemon and the two programs of the command line.
PROGRAMS = tesserad tessera tessera-render
# `make run` and `make build` leave the test suite as the build directory has it: a fresh clone is configured without
# it (it needs GTest, which only `make test` installs, and a third of a cold build), a build directory `make test`
# configured keeps it, so neither command reconfigures what the other set up; both build only $(PROGRAMS).
TESTS_CONFIGURED = $(shell sed -n 's/^TESSERA_BUILD_TESTS:BOOL=//p' $(BUILD)/CMakeCache.txt 2>/dev/null)
CMAKE_CONFIGURE = cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DTESSERA_ARCH=$(ARCH)

.PHONY: run test build configure deps test-deps asan fuzz-build fuzz bench image deb format clean

deps:
	deploy/install-deps.sh build

test-deps:
	deploy/install-deps.sh test

# Configuring again is quick (under a second) and takes a changed ARCH into an existing build directory.
configure:
	$(CMAKE_CONFIGURE) -DTESSERA_BUILD_TESTS=$(or $(TESTS_CONFIGURED),OFF)

build: deps configure
	cmake --build $(BUILD) -j $(JOBS) --target $(PROGRAMS)

run: build
	@mkdir -p $(DATA_DIR)
	exec $(BUILD)/server/tesserad --listen 127.0.0.1 --port $(PORT) --data-dir $(DATA_DIR)

test: test-deps fuzz-build
	$(CMAKE_CONFIGURE) -DTESSERA_BUILD_TESTS=ON
	cmake --build $(BUILD) -j $(JOBS)
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS) --timeout 900
	cd $(FUZZ_BUILD) && ctest --output-on-failure -j $(JOBS) -L fuzz --timeout 900

# The fuzz targets and only what they link (the build directory's `all`), with clang's libFuzzer and sanitizers.
fuzz-build: test-deps
	CC=clang-14 CXX=clang++-14 cmake -S . -B $(FUZZ_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Debug -DTESSERA_FUZZ=ON \
	  -DTESSERA_BUILD_TESTS=OFF
	cmake --build $(FUZZ_BUILD) -j $(JOBS)

# Each target FUZZ_SECONDS in turn; its log in FUZZ_FINDINGS/<target>.log, new inputs and crashes in
# FUZZ_FINDINGS/<target>/. A crash ends that target's run, and the command fails once every target has run: minimise
# the input (`$(FUZZ_BUILD)/tests/fuzz/fuzz_<target> -minimize_crash=1 -runs=10000 FILE`) and add it to
# tests/fuzz/corpus/<target>/ with the fix.
fuzz: fuzz-build
	@mkdir -p $(FUZZ_FINDINGS); failed=; for t in $(FUZZ_TARGETS); do \
	  echo "== fuzz_$$t for $(FUZZ_SECONDS) s, finds in $(FUZZ_FINDINGS)/$$t"; \
	  if tests/fuzz/run_fuzz.sh long $(FUZZ_BUILD)/tests/fuzz/fuzz_$$t tests/fuzz/corpus/$$t $(FUZZ_FINDINGS)/$$t \
	       $(FUZZ_SECONDS) 2>$(FUZZ_FINDINGS)/$$t.log; then grep -E '^(Done|stat::)' $(FUZZ_FINDINGS)/$$t.log; \
	  else tail -40 $(FUZZ_FINDINGS)/$$t.log; failed="$$failed $$t"; fi; \
	done; if [ -n "$$failed" ]; then echo "fuzz: findings of$$failed in $(FUZZ_FINDINGS)"; exit 1; fi

asan: test-deps
	cmake -S . -B $(ASAN_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTESSERA_SANITIZE=ON
	cmake --build $(ASAN_BUILD) -j $(JOBS)
	# A sanitizer report exits 86, which no test expects (tests that want "fatal" expect 1, the sanitizers' default).
	cd $(ASAN_BUILD) && ASAN_OPTIONS=exitcode=86:$$ASAN_OPTIONS UBSAN_OPTIONS=exitcode=86:print_stacktrace=1:$$UBSAN_OPTIONS \
	  ctest --output-on-failure -j $(JOBS) -LE slow --timeout 1800

bench: deps
	$(CMAKE_CONFIGURE) -DTESSERA_BUILD_TESTS=$(or $(TESTS_CONFIGURED),OFF) -DTESSERA_BUILD_BENCH=ON
	cmake --build $(BUILD) -j $(JOBS) --target tessera-bench tessera-poll-load tessera-claim-load tessera-denoise-bench

image:
	deploy/install-deps.sh deploy
	CONTAINERS_CONF=$(CURDIR)/deploy/podman/containers.conf deploy/podman/base-image.sh
	CONTAINERS_CONF=$(CURDIR)/deploy/podman/containers.conf podman build --format docker -f deploy/Dockerfile -t tessera:0.1.0 .

# A package is installed on other machines: built for any x86-64, without the tests, in its own directory.
deb: deps
	cmake -S . -B $(DEB_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DTESSERA_ARCH= -DTESSERA_BUILD_TESTS=OFF
	cmake --build $(DEB_BUILD) -j $(JOBS)
	cd $(DEB_BUILD) && cpack -G DEB

format:
	clang-format -i $$(git ls-files '*.cpp' '*.h')

clean:
	rm -rf $(BUILD) $(ASAN_BUILD) $(DEB_BUILD) $(FUZZ_BUILD)
