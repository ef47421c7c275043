#!/usr/bin/env bash
# The demo kitchen: vmacd plus four mock boards (washer, dishwasher, lights,
# and the dryer, which is user content: its driver, programmes and Lua plant
# are in examples/kitchen/, read with vmacd --drivers and vmac-board
# --plant-file, as docs/NEW_MACHINE.md makes them) in the foreground. Ctrl-C
# stops everything; every board ends with its outputs off. Usage:
# scripts/run-kitchen.sh [BIN_DIR] (default build/bin).
# Environment: VMAC_BUS (GROUP:PORT), VMAC_HTTP (ADDR:PORT), VMAC_TIME_SCALE
# (how fast the washer, dishwasher and dryer programmes run; default 0.1, ten
# times faster than real, so a demonstration wash takes minutes, not an hour),
# VMAC_STATE (the host's state folder; default build/state), VMAC_SET (more
# vmacd settings, KEY=VALUE items separated by spaces, each passed as --set
# after the demo's own, so they win: `make run VMAC_SET="miss_limit=3"`).
# Each run makes a fresh operate token in STATE/token (the previous one is
# revoked), and enrolls the four boards (their keys in STATE/keys).
#
# The demo's reply deadline is 10 ms, not vmacd's 4 ms: the boards here are
# processes on a PC that also runs builds and browsers, not microcontrollers,
# and a busy PC holds them off the CPU for longer than 4 ms now and then, the
# more so where they cannot have real-time scheduling (docs/KITCHEN.md, "On a
# busy machine"). 10 ms stays below the 16 ms period of the demo's quickest
# machines, so a reply still comes before the next request.
set -u
bin=${1:-build/bin}
bus=${VMAC_BUS:-239.255.86.77:5870}
http=${VMAC_HTTP:-127.0.0.1:8080}
scale=${VMAC_TIME_SCALE:-0.1}
state=${VMAC_STATE:-build/state}
deadline_us=10000
# The dryer's folder, whatever the current folder.
kitchen=$(cd "$(dirname "$0")/../examples/kitchen" && pwd) || exit 1

# The demo's slack on a loaded PC (docs/KITCHEN.md, "On a busy machine"):
# two misses in a row drop a machine, not one. Its boards act at the
# host's instants, their clocks locked to a SYNC a millisecond (TIME.md;
# each card shows its board's clock). VMAC_SET comes after and wins.
settings=(--set "driver.washer.param.time_scale=$scale" --set "driver.dishwasher.param.time_scale=$scale"
	--set "driver.dryer.param.time_scale=$scale" --set "miss_limit=2" --set "clock_sync_ms=1")
read -r -a extra <<<"${VMAC_SET:-}"
for item in ${extra[@]+"${extra[@]}"}; do
	case "$item" in
	reply_deadline_us=*) deadline_us=${item#*=} ;;
	?*=*) settings+=(--set "$item") ;;
	*)
		echo "run-kitchen: VMAC_SET takes KEY=VALUE items separated by spaces (docs/HOST.md lists the keys), got '$item'" >&2
		exit 2
		;;
	esac
done
settings+=(--set "reply_deadline_us=$deadline_us")

mkdir -p "$state" || exit 1
if [ -s "$state/token" ]; then
	old_id=$(cut -d_ -f2 "$state/token")
	"$bin/vmac" token revoke "$old_id" --state "$state" 2>/dev/null
fi
(umask 077 && "$bin/vmac" token create --state "$state" --scope operate --note "make run" >"$state/token") || {
	echo "run-kitchen: cannot make an access token in $state" >&2
	exit 1
}
# The demo's boards are enrolled (docs/SECURITY.md, "Enrolling boards"):
# each has its key in STATE/keys/NAME.key, made the first time, and the
# host trusts only boards whose announcement proves theirs.
"$bin/vmac" board enroll --local --state "$state" --key-dir "$state/keys" --replace --quiet \
	washer-1 dishwasher-1 lights-1 dryer-1 || {
	echo "run-kitchen: cannot enroll the demo's boards in $state" >&2
	exit 1
}
pids=()
fifos=$(mktemp -d)

# Background jobs get /dev/null as stdin unless told otherwise; the line
# reader below reads this terminal, so keep a handle on it.
exec 3<&0
reader=

# Ctrl-C in the terminal reaches every process of the kitchen at once, so
# then we only wait; a TERM (or a process ending) must be passed on.
stop() {
	trap - INT TERM
	echo
	echo "run-kitchen: stopping the host and the boards"
	[ "$1" = INT ] || kill -TERM "${pids[@]}" 2>/dev/null
	[ -n "$reader" ] && kill "$reader" 2>/dev/null
	exec 4>&- 5>&- 6>&- 7>&-
	wait
	rm -rf "$fifos"
	echo "run-kitchen: stopped"
	exit 0
}
trap 'stop INT' INT
trap 'stop TERM' TERM
"$bin/vmacd" --bus "$bus" --http "$http" --state "$state" --drivers "$kitchen" "${settings[@]}" &
pids+=($!)
# Each board reads operator actions from a FIFO; the loop at the end hands
# each line typed here to the board it names.
for b in washer-1 dishwasher-1 lights-1 dryer-1; do mkfifo "$fifos/$b"; done
# Each board's lines go to this terminal and, with the time, to
# STATE/boards.log, which `vmac logs --board-log` reads beside the host's
# events (docs/CLI.md, "vmac logs"): through a FIFO to a reader of its own,
# which stop() waits for, so that no board's last line is lost.
board_log() {
	local line
	while IFS= read -r line; do
		printf '%s\n' "$line"
		printf '%(%H:%M:%S)T %s\n' -1 "$line" >>"$state/boards.log"
	done
}
start_board() { # NAME, then vmac-board's arguments
	local name=$1
	shift
	mkfifo "$fifos/$name.out"
	board_log <"$fifos/$name.out" &
	"$bin/vmac-board" --name "$name" --bus "$bus" --key-dir "$state/keys" --quiet --commands "$@" \
		<"$fifos/$name" >"$fifos/$name.out" &
	pids+=($!)
}
start_board washer-1 --plant washer
start_board dishwasher-1 --plant dishwasher
start_board lights-1 --plant lights
start_board dryer-1 --plant-file "$kitchen/plants/dryer.lua"
exec 4>"$fifos/washer-1" 5>"$fifos/dishwasher-1" 6>"$fifos/lights-1" 7>"$fifos/dryer-1"

cat <<EOT

The demo kitchen is running.
  in a browser:  http://$http/#token=$(cat "$state/token")
                 (signs in with the operate token once; docs/UI.md)
  status:        VMAC_TOKEN_FILE=$state/token $bin/vmac status --http $http
  boards' lines: VMAC_TOKEN_FILE=$state/token $bin/vmac logs -f --http $http --board-log $state/boards.log
  status (JSON): curl -H "Authorization: Bearer \$(cat $state/token)" http://$http/api/status
                 (the API needs the token in $state/token: docs/API.md, "Access")
  type here, then Enter (docs/KITCHEN.md lists more):
    lights-1 toggle1 1        flip the kitchen wall switch
    washer-1 start 1          press the washer's start button (programme: normal)
    washer-1 door_release 1   open the washer door mid-wash (emergency release)
    washer-1 door 1           close it again
    washer-1 cancel 1         press cancel: the drum stops, the tub drains
    dishwasher-1 start 1      start the dishwasher
    dryer-1 start 1           start the dryer (programme: cotton; its files: examples/kitchen/)
    dryer-1 door 0            open the dryer door: no heat, the drum stops; dryer-1 door 1 closes it
  programmes run at time scale $scale (VMAC_TIME_SCALE); reply deadline $deadline_us us, two misses drop a machine${VMAC_SET:+ (VMAC_SET: $VMAC_SET)}
  Ctrl-C stops the host and the boards (all outputs off).

EOT
# Hand each typed line to the board it names (in the background, reading
# this terminal), while the script waits for a process of the kitchen to end.
dispatch() {
	while read -r line; do
		case "$line" in
		washer-1\ *) echo "$line" >&4 ;;
		dishwasher-1\ *) echo "$line" >&5 ;;
		lights-1\ *) echo "$line" >&6 ;;
		dryer-1\ *) echo "$line" >&7 ;;
		"") ;;
		*) echo "run-kitchen: start the line with a board's name: washer-1, dishwasher-1, lights-1 or dryer-1" ;;
		esac
	done
}
dispatch <&3 &
reader=$!
wait -n "${pids[@]}"
echo "run-kitchen: a process ended on its own; stopping the rest"
stop TERM
