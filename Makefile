# nanopush: the two commands a new user needs are `make run` and `make test`.
CARGO ?= cargo

.PHONY: run test setup build release fmt-check clippy unit web-test clean

## make run: build (release) and run the main job on the embedded default scene.
run: release
	./target/release/nanopush model

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

## Unit, property and end-to-end tests. The end-to-end tests run the real binaries, so they are
## built first.
unit: build
	$(CARGO) test --workspace

## The browser client's tests (web/: node --test on the protocol module).
web-test:
	cd web && npm ci --no-audit --no-fund && npm test

## make test: set up, then formatting, lints with -D warnings, and every test.
test: setup fmt-check clippy unit web-test

clean:
	$(CARGO) clean
