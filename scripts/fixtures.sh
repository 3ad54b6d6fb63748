#!/usr/bin/env bash
# Prints the shared fixtures directory for a checkout that has none beside it: `../shared/fixtures` next to this
# repository, else next to the repository it was cloned from (CI tests a fresh clone made elsewhere). Prints
# nothing when neither exists; the tests then name the missing fixture and AGENT_FIXTURES.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
if [[ -d ../shared/fixtures ]]; then
    (cd ../shared/fixtures && pwd)
    exit 0
fi
origin=$(git config --get remote.origin.url 2>/dev/null || true)
origin=${origin#file://}
if [[ -n "$origin" && -d "$origin/../shared/fixtures" ]]; then
    (cd "$origin/../shared/fixtures" && pwd)
fi
