#!/usr/bin/env bash
# Removes what scripts/install.sh installed under PREFIX (`make uninstall PREFIX=...`): the files its manifest
# (PREFIX/share/robot-agent/manifest) lists, after stopping and disabling the services. It keeps what is the
# administrator's or the robot's: the configuration in SYSCONFDIR/robot-agent, the state directory
# /var/lib/robot-agent (tokens, the pair database, recordings) and the services' user; it says how to remove them.
#
# usage: scripts/uninstall.sh [PREFIX]          PREFIX defaults to /usr/local; DESTDIR and SYSTEMCTL=no as for
#                                              install.sh
set -euo pipefail

prefix="${1:-${PREFIX:-/usr/local}}"
prefix="${prefix%/}"
destdir="${DESTDIR:-}"
destdir="${destdir%/}"
pkgdatadir="$prefix/share/robot-agent"
manifest="$destdir$pkgdatadir/manifest"

note() { echo "uninstall: $*"; }

if [[ ! -f "$manifest" ]]; then
    echo "uninstall: $manifest is missing: nothing was installed under ${destdir}${prefix}" >&2
    exit 1
fi

# Stop the services before their binaries go (for real only: a staged tree has no running services).
if [[ -z "$destdir" && "$(id -u)" == 0 && -d /run/systemd/system && "${SYSTEMCTL:-yes}" != no ]]; then
    units=()
    while read -r kind path; do
        [[ "$kind" == file && "$path" == *.service ]] && units+=("${path##*/}")
    done <"$manifest"
    if ((${#units[@]})); then
        # Disabling the template removes the links of all its instances (whisper-sat@1, @2, ...).
        systemctl stop 'whisper-sat@*.service' 2>/dev/null || true
        systemctl disable --now "${units[@]}" 2>/dev/null || true
    fi
fi

kept=()
while read -r kind path; do
    [[ -n "$path" ]] || continue
    if [[ "$kind" == conf ]]; then
        [[ -e "$destdir$path" ]] && kept+=("$path")
        continue
    fi
    rm -f "$destdir$path"
done <"$manifest"

# The folders install.sh made and that are now empty (share/robot-agent and its subfolders, the configuration's
# folder when nothing was kept).
if [[ -d "$destdir$pkgdatadir" ]]; then
    find "$destdir$pkgdatadir" -depth -type d -empty -delete
fi

if [[ -z "$destdir" && "$(id -u)" == 0 && -d /run/systemd/system && "${SYSTEMCTL:-yes}" != no ]]; then
    systemctl daemon-reload
fi
note "removed robot-agent from ${destdir}${prefix}"
for path in "${kept[@]}"; do
    note "kept $path (yours: remove it by hand)"
done
user="${SERVICE_USER:-robot-agent}"
note "kept the state directory /var/lib/robot-agent (tokens, pair database, recordings) and the user $user:"
note "  rm -rf /var/lib/robot-agent; userdel $user"
