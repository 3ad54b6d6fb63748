#!/usr/bin/env bash
# Installs robot-agent as a systemd service (`make install PREFIX=...`; docs/deploy.md): the release binaries, the
# default configuration (config/), the provisioned models, the systemd units rendered from deploy/ with this
# prefix's paths, and an editable configuration and environment in SYSCONFDIR/robot-agent. Every file it writes is
# listed in PREFIX/share/robot-agent/manifest, which scripts/uninstall.sh reads.
#
# usage: scripts/install.sh [PREFIX]            PREFIX defaults to /usr/local
# environment (all optional):
#   DESTDIR       stage the files under this directory (packaging): no user is made and systemd is not told
#   BIN_DIR       the binaries to install (default: $CARGO_TARGET_DIR/release, else target/release)
#   ROLE          all (default): the agent and its satellites; satellites: only whisper-sat and llm-sat, for a hub
#                 on another machine (their units then do not wait for a local robot-agent)
#   MODELS        copy (default): copy the model files into PREFIX/share/robot-agent/models; link: a symbolic link
#                 to this checkout's models/ instead (the services must be able to read it: not under /home or
#                 /root, which ProtectHome hides from them)
#   SYSCONFDIR    default: /etc for PREFIX /usr or /usr/local, else PREFIX/etc
#   UNITDIR       default: PREFIX/lib/systemd/system for /usr and /usr/local (on systemd's search path), else
#                 /etc/systemd/system
#   SERVICE_USER  the user the services run as (default robot-agent); made as a system user when installing as
#                 root without DESTDIR, unless CREATE_USER=no
#   SYSTEMCTL     no: do not tell a running systemd about the units (tests/install.rs installs into a temporary
#                 PREFIX with SYSTEMCTL=no CREATE_USER=no, touching nothing outside it)
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
prefix="${1:-${PREFIX:-/usr/local}}"
prefix="${prefix%/}"
destdir="${DESTDIR:-}"
destdir="${destdir%/}"
bin_dir="${BIN_DIR:-${CARGO_TARGET_DIR:-$root/target}/release}"
role="${ROLE:-all}"
models_mode="${MODELS:-copy}"
user="${SERVICE_USER:-robot-agent}"

die() {
    echo "install: $*" >&2
    exit 1
}
note() { echo "install: $*"; }

[[ "$prefix" == /* ]] || die "PREFIX must be an absolute path, not '$prefix'"
# The paths go into sed expressions and unit files: keep them to characters that need no quoting there.
for path in "$prefix" "${SYSCONFDIR:-}" "${UNITDIR:-}"; do
    [[ "$path" =~ ^[A-Za-z0-9_./+-]*$ ]] || die "'$path' has characters a unit file path cannot take unquoted"
done
[[ "$user" =~ ^[a-z_][a-z0-9_-]*$ ]] || die "SERVICE_USER '$user' is not a user name"
case "$role" in all | satellites) ;; *) die "ROLE is all or satellites, not '$role'" ;; esac
case "$models_mode" in copy | link) ;; *) die "MODELS is copy or link, not '$models_mode'" ;; esac
if [[ "$models_mode" == link && ! -d "$root/models" ]]; then
    die "$root/models does not exist: provision the models first (make run does), or install with MODELS=copy"
fi

case "$prefix" in
    /usr | /usr/local) sysconfdir="${SYSCONFDIR:-/etc}" unitdir="${UNITDIR:-$prefix/lib/systemd/system}" ;;
    *) sysconfdir="${SYSCONFDIR:-$prefix/etc}" unitdir="${UNITDIR:-/etc/systemd/system}" ;;
esac
bindir="$prefix/bin"
pkgdatadir="$prefix/share/robot-agent"
confdir="$sysconfdir/robot-agent"

binaries=(whisper-sat llm-sat)
if [[ "$role" == all ]]; then
    binaries=(robot-agent "${binaries[@]}")
fi
for b in "${binaries[@]}"; do
    [[ -x "$bin_dir/$b" ]] || die "$bin_dir/$b is missing: build it first (make build), or name the binaries with BIN_DIR"
done

# The manifest lists what this run installed, one "file PATH" or "conf PATH" (kept by uninstall) per line, without
# DESTDIR; an earlier install's list is replaced.
manifest_entries=()
put() { # MODE SOURCE DEST [conf]: installs one file and lists it
    install -D -m "$1" "$2" "$destdir$3"
    manifest_entries+=("${4:-file} $3")
}

for b in "${binaries[@]}"; do
    put 0755 "$bin_dir/$b" "$bindir/$b"
done
# flowctl, the operator's tool (`flowctl channels` against the running hub), when it was built.
if [[ -x "$bin_dir/flowctl" ]]; then
    put 0755 "$bin_dir/flowctl" "$bindir/flowctl"
fi

# The default configuration: the rule programs that the service reads from its working directory (config/brain.tr,
# config/brain.it.tr), the Italian overlay, the embedded defaults for reference, and the models' checksums.
for f in "$root"/config/*; do
    put 0644 "$f" "$pkgdatadir/config/${f##*/}"
done
put 0644 "$root/docs/deploy.md" "$pkgdatadir/docs/deploy.md"
# The example knowledge folder ([agent] knowledge = "knowledge/", docs/knowledge.md): edit it there for this place.
for f in "$root"/knowledge/*; do
    put 0644 "$f" "$pkgdatadir/knowledge/${f##*/}"
done

# The models: only the files the programs load (not the download cache or the Python environments of models/).
mkdir -p "$destdir$pkgdatadir"
if [[ "$models_mode" == link ]]; then
    case "$root" in
        /home/* | /root/* | /run/user/*)
            note "warning: $root is hidden from the services by ProtectHome=yes; use MODELS=copy, or a drop-in with ProtectHome=read-only"
            ;;
    esac
    rm -rf "$destdir$pkgdatadir/models"
    ln -s "$root/models" "$destdir$pkgdatadir/models"
    manifest_entries+=("file $pkgdatadir/models")
else
    [[ -L "$destdir$pkgdatadir/models" ]] && rm -f "$destdir$pkgdatadir/models"
    shopt -s nullglob
    model_files=("$root"/models/ggml-*.bin "$root"/models/centerface.onnx "$root"/models/dlib/*.dat
        "$root"/models/piper/*.durations.onnx
        "$root"/models/piper/*.onnx.json "$root"/models/onnxruntime/libonnxruntime.so* "$root"/models/llm/*.gguf)
    shopt -u nullglob
    for f in "${model_files[@]}"; do
        [[ -f "$f" ]] || continue
        put 0644 "$f" "$pkgdatadir/${f#"$root"/}"
    done
fi
missing=()
have_model() { [[ -e "$destdir$pkgdatadir/models/$1" ]]; }
have_model ggml-tiny.en.bin || missing+=("models/ggml-tiny.en.bin (make model): whisper-sat's default model")
if [[ "$role" == all ]]; then
    have_model centerface.onnx || missing+=("models/centerface.onnx (make model-face): the faces are found by OpenCV's cascades instead")
    have_model dlib/shape_predictor_68_face_landmarks.dat ||
        missing+=("models/dlib (make model-face): the per-face analysis (who looks, smiles, talks) is off")
fi
have_model llm/SmolLM2-135M-Instruct.Q4_1.gguf ||
    missing+=("models/llm/SmolLM2-135M-Instruct.Q4_1.gguf (make model-llm): llm-sat's default model")
for m in "${missing[@]}"; do
    note "warning: not provisioned: $m"
done

# The units and the editable files, rendered with this prefix's paths.
if [[ "$role" == all ]]; then
    lines=(-e '/^@REMOTE@/d' -e 's/^@LOCAL@//')
else
    lines=(-e '/^@LOCAL@/d' -e 's/^@REMOTE@//')
fi
if have_model centerface.onnx; then
    lines+=(-e '/^@NO_CENTERFACE@/d')
else
    lines+=(-e 's/^@NO_CENTERFACE@//')
fi
if have_model dlib/shape_predictor_68_face_landmarks.dat && have_model dlib/dlib_face_recognition_resnet_model_v1.dat; then
    lines+=(-e '/^@NO_DLIB@/d')
else
    lines+=(-e 's/^@NO_DLIB@//')
fi
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
render() { # TEMPLATE: deploy/TEMPLATE.in rendered into $scratch/TEMPLATE
    sed -e "s|@BINDIR@|$bindir|g" -e "s|@PKGDATADIR@|$pkgdatadir|g" -e "s|@CONFDIR@|$confdir|g" \
        -e "s|@USER@|$user|g" "${lines[@]}" "$root/deploy/$1.in" >"$scratch/$1"
}
units=(whisper-sat@.service llm-sat.service)
if [[ "$role" == all ]]; then
    units=(robot-agent.service "${units[@]}")
fi
for u in "${units[@]}"; do
    render "$u"
    put 0644 "$scratch/$u" "$unitdir/$u"
done

# The configuration and the environment are the administrator's once written: kept on a reinstall, with the new
# rendering beside them as NAME.new when it differs. The environment may hold a token: readable by root only
# (systemd reads it before it drops to the service's user).
conf() { # NAME MODE
    render "$1"
    local dest="$confdir/$1"
    if [[ -e "$destdir$dest" ]] && ! cmp -s "$scratch/$1" "$destdir$dest"; then
        install -D -m "$2" "$scratch/$1" "$destdir$dest.new"
        note "kept your $dest; this version's is $dest.new"
        manifest_entries+=("conf $dest.new")
    elif [[ ! -e "$destdir$dest" ]]; then
        install -D -m "$2" "$scratch/$1" "$destdir$dest"
    fi
    manifest_entries+=("conf $dest")
}
if [[ "$role" == all ]]; then
    conf robot-agent.toml 0644
fi
conf robot-agent.env 0600

printf '%s\n' "${manifest_entries[@]}" "file $pkgdatadir/manifest" >"$scratch/manifest"
install -D -m 0644 "$scratch/manifest" "$destdir$pkgdatadir/manifest"

# For real (not staged): the services' user, and systemd told about the new units.
if [[ -z "$destdir" && "$(id -u)" == 0 ]]; then
    if ! id "$user" >/dev/null 2>&1 && [[ "${CREATE_USER:-yes}" != no ]]; then
        useradd --system --user-group --home-dir /nonexistent --no-create-home --shell /usr/sbin/nologin \
            --comment "robot-agent services" "$user"
        note "made the system user $user"
    fi
    if [[ -d /run/systemd/system && "${SYSTEMCTL:-yes}" != no ]]; then
        systemctl daemon-reload
    fi
fi
id "$user" >/dev/null 2>&1 || [[ -n "$destdir" ]] ||
    note "warning: there is no user $user yet: make it (useradd --system --user-group $user) before starting the services"

note "installed into ${destdir}${prefix} (units in $unitdir, configuration in $confdir)"
if [[ "$role" == all ]]; then
    note "start it at boot: systemctl enable --now robot-agent whisper-sat@1 llm-sat"
    note "the page's address: journalctl -u robot-agent | grep 'ready: open'  (token: /var/lib/robot-agent/page.token)"
else
    note "set FLOW_ADDR and FLOW_TOKEN in $confdir/robot-agent.env, then: systemctl enable --now whisper-sat@1 llm-sat"
fi
