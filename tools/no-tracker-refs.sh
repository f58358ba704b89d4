#!/usr/bin/env bash
# Fails if a tracked file refers to this project's tracker or work log ("issue 12", "issue-4",
# "item 7 of", "stop 15") instead of saying what is meant. Links to other projects' issues
# (github.com/OWNER/REPO/issues/123) are fine: they are URLs, not prose references.
# Usage: tools/no-tracker-refs.sh   (from anywhere in the repository; exits 1 listing offenders)
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

pattern='\b[Ii]ssues? [0-9]+|\b[Ii]ssue-[0-9]+|\b[Ii]tems? [0-9]+( of|\b)|\b[Ss]top [0-9]+\b'

# -I skips binary files (the weight blobs); the figures are generated SVG. Outside a git checkout
# (an unpacked archive) every file but build output is searched.
search() {
    if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
        git grep -nIE "$pattern" -- . ':!*.svg' ':!tools/no-tracker-refs.sh'
    else
        grep -rnIE "$pattern" --exclude='*.svg' --exclude=no-tracker-refs.sh \
            --exclude-dir=target --exclude-dir=.git --exclude-dir=out .
    fi
}
if offenders=$(search); then
    echo "tracker references found (say what is meant, or link the docs page):" >&2
    echo "$offenders" >&2
    exit 1
fi
echo "no tracker references"
