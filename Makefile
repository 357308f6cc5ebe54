# nanopush: the two commands a new user needs are `make run` and `make test`.
CARGO ?= cargo

.PHONY: run web test setup build release fmt-check clippy no-default-features unit web-test prometheus-check mutants clean

## make run: build (release), install the web client's packages, and start the teleoperation
## server on the embedded default scene; it prints the URL to open (with the operator token).
run: release web
	./target/release/nanopush serve

## The web client: its packages (three, uPlot, esbuild) from npm, again whenever
## package-lock.json is newer than what npm installed (a checkout from before esbuild had
## node_modules without it: `esbuild: not found`), and the minified page (web/dist/, by esbuild).
web:
	@test web/node_modules/.package-lock.json -nt web/package-lock.json || (cd web && npm ci --no-audit --no-fund)
	cd web && npm run build

release:
	$(CARGO) build --release --workspace --bins

build:
	$(CARGO) build --workspace --bins

## make setup: install what the tests need on a fresh Debian machine (idempotent).
setup:
	bash .ci/setup

fmt-check:
	$(CARGO) fmt --all -- --check

clippy:
	$(CARGO) clippy --workspace --all-targets -- -D warnings

## The workspace without its default features (`nanopush` without the peer solvers of
## `nanopush accuracy`): the lints, then the tests of the work-precision report's points and
## command, the one thing the feature changes (the other tests would run the same code again).
no-default-features:
	$(CARGO) clippy --workspace --all-targets --no-default-features -- -D warnings
	$(CARGO) test -p nanopush-study -p nanopush-cli --no-default-features -- accuracy::tests accuracy_cmd::

## Unit, property and end-to-end tests. The end-to-end tests run the real binaries, so they are
## built first.
unit: build
	$(CARGO) test --workspace

## The browser client's tests: node --test on its modules, then the browser end-to-end tests
## (web/e2e/: Debian's headless chromium, driven by playwright-core, against the real
## `nanopush serve` from target/debug or $CARGO_TARGET_DIR; screenshots in web/test-results/).
web-test: build
	cd web && npm ci --no-audit --no-fund && npm run build && npm test && npm run e2e

## The lab's monitoring: the shipped Prometheus config and its alert rules (deploy/prometheus/).
prometheus-check:
	promtool check config deploy/prometheus/prometheus.yml
	promtool test rules deploy/prometheus/alerts_test.yml

## make test: set up, then formatting, lints with -D warnings (with and without the default
## features), and every test.
test: setup fmt-check clippy no-default-features prometheus-check unit web-test

## make mutants: mutation testing with cargo-mutants (from crates.io, installed on first use) on
## the physics, the integrators, the control and the protocol's validation, against the library's
## tests (`-C --lib`: each mutant builds only the library's test binary, not the binaries,
## examples and integration tests too: 2-3 s a build instead of 7). Not part of `make test`: ~3600
## mutants, hours on 2 cores. Results in mutants.out/; `--iterate` in CARGO_MUTANTS_ARGS re-runs
## only what a previous run did not catch.
## MUTANTS_FILES narrows it, e.g. make mutants MUTANTS_FILES='instrument/src/numerics/integrate/*.rs';
## MUTANTS_TESTS holds the library test filters the mutants run against, one or several (they go
## to the test binary: MUTANTS_TESTS='physics:: numerics::'). Test-only modules
## (tests.rs, *_tests.rs, the Eq 17 reference) are not mutated.
MUTANTS_FILES ?= instrument/src/physics/**/*.rs instrument/src/numerics/**/*.rs instrument/src/control/**/*.rs server/src/command_checks.rs proto/src/**/*.rs
MUTANTS_TESTS ?=
CARGO_MUTANTS_ARGS ?=
mutants:
	@command -v cargo-mutants >/dev/null || $(CARGO) install cargo-mutants --version 27.1.0 --locked
	$(CARGO) mutants --workspace $(CARGO_MUTANTS_ARGS) $(foreach f,$(MUTANTS_FILES),-f '$(f)') \
	  -e '**/tests.rs' -e '**/tests/**' -e '**/*_tests.rs' -e '**/test_problems.rs' \
	  -e '**/eq17_reference.rs' --timeout-multiplier 3 \
	  -C --lib -- -- $(MUTANTS_TESTS)

clean:
	$(CARGO) clean
