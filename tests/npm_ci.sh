#!/bin/sh
# The test tooling from npm, in one place: makes sure Node.js (at least
# MIN_MAJOR) and npm are here, installing Debian's nodejs and npm when they
# are missing or too old, then installs DIR's packages at the versions its
# package-lock.json pins (npm ci). Used by tests/ui/run.sh (playwright-core)
# and make test-integration (tests/mqtt/tahu: Eclipse Tahu's Sparkplug codec).
# Exit 0 when DIR is ready; otherwise exit 1 with one line on standard error
# saying why (the caller decides whether that is a skip or, under CI, a
# failure).
#
#   tests/npm_ci.sh DIR MIN_MAJOR
set -u
dir=$1
min=$2
sudo=""
[ "$(id -u)" = 0 ] || sudo=sudo

node_ok() {
	command -v node >/dev/null && command -v npm >/dev/null &&
		[ "$(node -p 'process.versions.node.split(".")[0]')" -ge "$min" ]
}

if ! node_ok; then
	echo "npm_ci: installing Debian's nodejs and npm"
	$sudo apt-get update -qq && $sudo env DEBIAN_FRONTEND=noninteractive \
		apt-get install -y -qq --no-install-recommends nodejs npm >/dev/null
fi
if ! node_ok; then
	echo "$dir needs Node.js $min or later and npm, and this machine has $(node --version 2>/dev/null || echo no node)" >&2
	exit 1
fi
# Already installed at the pinned versions: nothing to fetch.
if [ -f "$dir/node_modules/.package-lock.json" ] && cmp -s "$dir/package-lock.json" "$dir/node_modules/.vmac-lock"; then
	exit 0
fi
if ! (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error >/dev/null); then
	echo "npm ci in $dir failed (is the npm registry reachable?)" >&2
	exit 1
fi
cp "$dir/package-lock.json" "$dir/node_modules/.vmac-lock"
