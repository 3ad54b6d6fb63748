#!/usr/bin/env bash
# Installs the Debian packages the project needs to build, run, test and benchmark, skipping those already present,
# so that `make run` and `make test` work on a fresh Debian 12 machine.
set -euo pipefail

packages=(
    build-essential pkg-config libssl-dev curl ca-certificates git
    clang libclang-dev cmake                 # bindgen for opencv; whisper.cpp and espeak-ng builds
    libopencv-dev opencv-data                # OpenCV 4.6 and its Haar/LBP cascades
    libdlib-dev libblas-dev liblapack-dev    # dlib for the per-face analysis (agent/face), with the BLAS it calls
    libopenblas0-pthread                     # ... served by OpenBLAS: the face descriptor 15 ms instead of 210 ms
    libsonic-dev espeak-ng espeak-ng-data    # speech synthesis
    python3 python3-pip python3-venv         # model download (pip), Python baselines in benchmarks
    chromium chromium-driver                 # headless end-to-end tests
    ffmpeg sox                               # fixture conversion for fake camera / microphone devices
    flite                                    # spoken questions for the full-pipeline test (a voice not our own)
    redis-server                             # hub benchmark baseline
    libspeexdsp-dev                          # echo-bench's baseline: Speex's echo canceller
    # Real Italian speech with its transcripts for the Italian conversation test: the Asterisk prompts recorded by
    # Carlo Flora (CC-BY-3.0), 8 kHz WAV under /usr/share/asterisk/sounds/it_IT_m_Carlo, text in the doc directory.
    asterisk-core-sounds-it-wav asterisk-core-sounds-it
    # More real English read speech for the ASR benchmark's word error rates: LibriVox clips with transcription.
    pocketsphinx-testdata
    socat                                    # linked pseudo-terminals: serial lines in tests and benchmarks
)

# The embedded target flow-lite is built for in `make test`, to prove it needs no std (rustup fetches it once).
if command -v rustup >/dev/null && ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
    echo "deps: adding the Rust target thumbv7em-none-eabihf"
    rustup target add thumbv7em-none-eabihf
fi

# cargo-nextest runs the Rust suites in `make test`: a process per test, so a test that hangs is ended at its ceiling
# (.config/nextest.toml) and the rest still run. The machines' image has it; a bare one builds it once from crates.io.
if ! cargo nextest --version >/dev/null 2>&1; then
    echo "deps: installing cargo-nextest"
    cargo install --locked cargo-nextest --version '^0.9'
fi

missing=()
for p in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed"; then
        missing+=("$p")
    fi
done

if ((${#missing[@]} == 0)); then
    echo "deps: all system packages present"
    exit 0
fi

echo "deps: installing ${missing[*]}"
sudo=""
if [[ $(id -u) -ne 0 ]]; then
    sudo="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
# Debian's redis-server package starts a system instance; the benchmark starts its own on a free port.
if [[ " ${missing[*]} " == *" redis-server "* ]]; then
    $sudo systemctl disable --now redis-server >/dev/null 2>&1 || true
fi
