#!/usr/bin/env bash
# Runs a test command (`cargo test ...`) with its output passed through, and when it fails, ends with a digest: each
# failed test's name and the first lines of its error. A CI log is often read from its tail, where cargo prints only
# which test binaries failed; the digest says which tests and why without scrolling back. The exit status is kept.
#
#   scripts/test-digest.sh COMMAND [ARG...]
set -uo pipefail

log=$(mktemp)
trap 'rm -f "$log"' EXIT
"$@" 2>&1 | tee "$log"
status=${PIPESTATUS[0]}
if ((status != 0)); then
    echo "failed tests (first lines of each one's error):"
    awk '
        /^---- .* stdout ----$/ { name = $2; left = 2; next }
        /^(failures|successes):$/ { name = "" }
        name != "" && left > 0 && (/^Error: / || /panicked at/ || after) {
            if (left == 2) printf "  %s: ", name; else printf "    ";
            print substr($0, 1, 240);
            after = /panicked at/; left--;
            next
        }
    ' "$log" | head -n 40
fi
exit "$status"
