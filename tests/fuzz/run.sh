#!/bin/sh
# make fuzz and make test-fuzz (docs/TESTING.md, "Fuzzing"): each target
# given, SECONDS long, in JOBS fuzzer processes at once sharing its corpus
# (libFuzzer reads what the others found every second); then, for the
# targets that run Lua from a snapshot of their sandbox (tests/fuzz/
# fuzz_arena.c), every input of the corpus again with VMAC_FUZZ_FRESH=1:
# each in a fresh sandbox on the C library's heap under ASan, as the host
# runs drivers. Prints each target's executions and the total. A failure
# (crash, sanitizer report, leak, out of memory, an input over 10 s) is
# printed with its log and input, and fails the run once every target has
# had its turn. The fuzzing processes record two frames of each
# allocation's stack (ASAN_OPTIONS=malloc_context_size=2; ASan's 30 cost
# the targets that allocate most a quarter of their inputs): a report names
# the functions that allocated and freed; replaying the kept input
# (build/fuzz/fuzz_NAME FILE) gives whole stacks. Run from the source tree
# (the manifest target reads stdlib/).
#
#   tests/fuzz/run.sh BUILD SECONDS JOBS TARGET...
set -u
if [ $# -lt 4 ]; then
	echo "usage: $0 BUILD SECONDS JOBS TARGET..." >&2
	exit 2
fi
build=$1 seconds=$2 jobs=$3
shift 3
total=0
failed=
for t in "$@"; do
	bin=$build/fuzz/fuzz_$t
	work=$build/fuzz/work-$t
	mkdir -p "$work"
	rm -f "$build/fuzz/$t".*.log
	dict=
	[ -f "tests/fuzz/$t.dict" ] && dict=-dict=tests/fuzz/$t.dict
	seeds=
	if [ "$t" = manifest ]; then
		# The shipped drivers, each as the host loads it: announced by its
		# name (a --!name line), so vmac.cycles() finds its programmes.
		seeds=$build/fuzz/seeds-manifest
		rm -rf "$seeds"
		mkdir -p "$seeds"
		for f in scripts/drivers/*.lua; do
			name=$(basename "$f" .lua)
			{
				echo "--!name=$name"
				cat "$f"
			} >"$seeds/$name.lua"
			# Each must load and attach in the harness, or its driver
			# would go unfuzzed with nothing said.
			if ! VMAC_FUZZ_MUST_LOAD=1 "$bin" "$seeds/$name.lua" >"$build/fuzz/$t.seed.log" 2>&1; then
				tail -n 20 "$build/fuzz/$t.seed.log"
				echo "fuzz_$t: the shipped driver $f does not load in the harness"
				failed="$failed $t"
				continue 2
			fi
		done
	fi
	pids=
	j=1
	while [ "$j" -le "$jobs" ]; do
		# shellcheck disable=SC2086 # dict and seeds are empty or one word
		ASAN_OPTIONS="malloc_context_size=2${ASAN_OPTIONS:+:$ASAN_OPTIONS}" \
			"$bin" -max_total_time="$seconds" -timeout=10 -artifact_prefix="$build/fuzz/$t-" $dict \
			"$work" "tests/fuzz/corpus-$t" $seeds >"$build/fuzz/$t.$j.log" 2>&1 &
		pids="$pids $!"
		j=$((j + 1))
	done
	runs=0
	bad=
	j=1
	for p in $pids; do
		log=$build/fuzz/$t.$j.log
		if wait "$p"; then
			n=$(sed -n 's/^Done \([0-9]*\) runs.*/\1/p' "$log")
			runs=$((runs + ${n:-0}))
		else
			bad="$bad $log"
		fi
		j=$((j + 1))
	done
	fresh=
	case $t in manifest | values | checkpoint)
		log=$build/fuzz/$t.fresh.log
		# shellcheck disable=SC2086
		if [ -z "$bad" ] && VMAC_FUZZ_FRESH=1 "$bin" -runs=0 -timeout=10 -artifact_prefix="$build/fuzz/$t-fresh-" \
			"$work" "tests/fuzz/corpus-$t" $seeds >"$log" 2>&1; then
			fresh=", $(sed -n 's/^Done \([0-9]*\) runs.*/\1/p' "$log") kept inputs again in fresh sandboxes"
		elif [ -z "$bad" ]; then
			bad=" $log"
		fi
		;;
	esac
	if [ -n "$bad" ]; then
		for log in $bad; do
			tail -n 60 "$log"
		done
		echo "fuzz_$t found a failure: the input is $build/fuzz/$t-*, the log$bad"
		failed="$failed $t"
	else
		printf '  %-10s %10s executions in %s s, %s processes%s\n' "$t" "$runs" "$seconds" "$jobs" "$fresh"
		total=$((total + runs))
	fi
done
printf '  %-10s %10s executions\n' total "$total"
if [ -n "$failed" ]; then
	echo "fuzzing failed:$failed"
	exit 1
fi
