#!/usr/bin/env bash
# The demo kitchen with its boards on emulated microcontrollers: vmacd on raw
# Ethernet, and each board the LM3S6965 firmware (make firmware) in QEMU's
# lm3s6965evb machine, its Ethernet MAC on a tap device. The taps are ports
# of one Linux bridge, and vmacd listens on the bridge (--bus eth:BRIDGE), so
# any number of QEMU boards share one link. Each board gets a copy of the
# image with its own name and MAC (scripts/qemu-board-config.py). Needs root
# (tap devices, a bridge, CAP_NET_RAW). Ctrl-C stops the host (which tells
# every board to turn its outputs off), then QEMU, and removes the devices.
#
# Usage: scripts/run-qemu-kitchen.sh [BIN_DIR] [FIRMWARE_ELF]
#   (default build/bin and build/firmware/vmac-board-lm3s6965.elf)
# Environment: VMAC_HTTP (ADDR:PORT), VMAC_TIME_SCALE (default 0.1), VMAC_STATE
# (default build/state; a fresh operate token in STATE/token each run),
# VMAC_QEMU_BOARDS (PLANT:NAME ..., default "washer:washer-1
# dishwasher:dishwasher-1 lights:lights-1"), VMAC_QEMU_NET (prefix of the
# device names, default vmq: bridge vmqbr, taps vmqtap1..), VMAC_QEMU_DEADLINE_US
# (the host's reply deadline, default 20000: an emulated board usually
# answers well within vmacd's default 4 ms, but on a small machine running
# three of them QEMU now and then takes longer), VMAC_SET (more vmacd
# settings, KEY=VALUE items separated by spaces, each passed as --set after
# the script's own, so they win, as for scripts/run-kitchen.sh).
set -u
bin=${1:-build/bin}
image=${2:-build/firmware/vmac-board-lm3s6965.elf}
http=${VMAC_HTTP:-127.0.0.1:8080}
scale=${VMAC_TIME_SCALE:-0.1}
state=${VMAC_STATE:-build/state}
boards=${VMAC_QEMU_BOARDS:-washer:washer-1 dishwasher:dishwasher-1 lights:lights-1}
net=${VMAC_QEMU_NET:-vmq}
deadline_us=${VMAC_QEMU_DEADLINE_US:-20000}
bridge=${net}br
here=$(dirname "$0")

settings=(--set "driver.washer.param.time_scale=$scale" --set "driver.dishwasher.param.time_scale=$scale")
read -r -a extra <<<"${VMAC_SET:-}"
for item in ${extra[@]+"${extra[@]}"}; do
	case "$item" in
	reply_deadline_us=*) deadline_us=${item#*=} ;;
	?*=*) settings+=(--set "$item") ;;
	*)
		echo "run-qemu-kitchen: VMAC_SET takes KEY=VALUE items separated by spaces (docs/HOST.md lists the keys), got '$item'" >&2
		exit 2
		;;
	esac
done
settings+=(--set "reply_deadline_us=$deadline_us")

say() { echo "run-qemu-kitchen: $*"; }
die() {
	echo "run-qemu-kitchen: $*" >&2
	exit 1
}

[ "$(id -u)" = 0 ] || die "needs root: tap devices, a bridge and raw Ethernet (sudo $0 $*)"
command -v qemu-system-arm >/dev/null || die "no qemu-system-arm (make deps installs it)"
[ -f "$image" ] || die "no firmware image $image (make firmware)"
for p in vmacd vmac; do [ -x "$bin/$p" ] || die "no $bin/$p (make)"; done

# Devices of an earlier run that did not get to clean up (they carry our names).
remove_devices() {
	local dev
	for dev in $(ip -o link show 2>/dev/null | awk -F': ' '{print $2}' | sed 's/@.*//' | grep -E "^${net}tap[0-9]+$"); do
		ip link del "$dev" 2>/dev/null
	done
	ip link del "$bridge" 2>/dev/null
}
if ip link show "$bridge" >/dev/null 2>&1; then
	say "removing $bridge and its taps, left by an earlier run"
	remove_devices
fi

mkdir -p "$state" || exit 1
if [ -s "$state/token" ]; then
	old_id=$(cut -d_ -f2 "$state/token")
	"$bin/vmac" token revoke "$old_id" --state "$state" 2>/dev/null
fi
(umask 077 && "$bin/vmac" token create --state "$state" --scope operate --note "make run-qemu" >"$state/token") ||
	die "cannot make an access token in $state"

# Background jobs get /dev/null as stdin unless told otherwise; the line
# reader at the end reads this terminal, so keep a handle on it.
exec 3<&0
work=$(mktemp -d)
host_pid=
qemu_pids=()
cat_pids=()
uart_fds=()
names=()
reader=
cleanup() {
	trap - INT TERM HUP
	trap '' PIPE # a terminal gone: clean up all the same
	echo
	say "stopping the host, then the boards"
	[ -n "$reader" ] && kill "$reader" 2>/dev/null
	if [ -n "$host_pid" ]; then
		kill -TERM "$host_pid" 2>/dev/null # it sends SHUTDOWN to every board and waits for their answers
		wait "$host_pid" 2>/dev/null
	fi
	sleep 0.2 # the last lines of the boards' logs
	[ ${#qemu_pids[@]} -gt 0 ] && kill -TERM "${qemu_pids[@]}" 2>/dev/null
	[ ${#qemu_pids[@]} -gt 0 ] && wait "${qemu_pids[@]}" 2>/dev/null
	[ ${#cat_pids[@]} -gt 0 ] && kill "${cat_pids[@]}" 2>/dev/null # ended by now, at the end of QEMU's output
	wait 2>/dev/null
	remove_devices
	rm -rf "$work"
	say "stopped; $bridge and its taps removed"
	exit 0
}
trap cleanup INT TERM HUP

# The link: a bridge with a fixed address (vmacd sends from the address it
# reads at start; a bridge would otherwise take its lowest port's), no STP,
# no IPv6 chatter; one tap per board.
ip link add "$bridge" type bridge stp_state 0 forward_delay 0 || die "cannot make the bridge $bridge"
ip link set "$bridge" address 02:00:00:00:00:fe
sysctl -qw "net.ipv6.conf.$bridge.disable_ipv6=1" 2>/dev/null
ip link set "$bridge" up
n=0
for spec in $boards; do
	n=$((n + 1))
	plant=${spec%%:*}
	name=${spec#*:}
	tap=${net}tap$n
	ip tuntap add dev "$tap" mode tap || {
		remove_devices
		die "cannot make the tap device $tap"
	}
	sysctl -qw "net.ipv6.conf.$tap.disable_ipv6=1" 2>/dev/null
	ip link set "$tap" master "$bridge"
	ip link set "$tap" up
	# Enrolled, its key in STATE/keys/NAME.key (made the first time) and in
	# its copy's identity block (docs/SECURITY.md, "Enrolling boards").
	"$bin/vmac" board enroll --local --state "$state" --key-dir "$state/keys" --replace --quiet "$name" || {
		remove_devices
		die "cannot enroll board $name in $state"
	}
	out=$(python3 "$here/qemu-board-config.py" "$image" -o "$work/$name.elf" --plant "$plant" --name "$name" \
		--key-file "$state/keys/$name.key" --quiet) || {
		remove_devices
		die "cannot configure board $name"
	}
	mac=$(echo "$out" | sed -n 's/.*, mac \([0-9a-f:]*\),.*/\1/p')
	mkfifo "$work/$name.in" "$work/$name.out"
	# Its UART0 is its stdio: input from a FIFO the line reader below
	# writes to, output through cat to this terminal (QEMU makes its
	# stdout non-blocking, which the terminal this script reads must not
	# be). cat ignores Ctrl-C, so the board's last lines still show.
	(
		trap '' INT
		exec cat <"$work/$name.out"
	) &
	cat_pids+=($!)
	# Its own session: Ctrl-C reaches the host, which tells the board to
	# go safe; QEMU is stopped after that.
	setsid qemu-system-arm -M lm3s6965evb -display none -monitor none -serial stdio \
		-nic "tap,ifname=$tap,script=no,downscript=no,model=stellaris,mac=$mac" \
		-kernel "$work/$name.elf" <"$work/$name.in" >"$work/$name.out" &
	qemu_pids+=($!)
	names+=("$name")
	exec {fd}>"$work/$name.in" # held open: QEMU's UART input never sees an end
	uart_fds+=("$fd")
done

"$bin/vmacd" --bus "eth:$bridge" --http "$http" --state "$state" "${settings[@]}" &
host_pid=$!

cat <<EOT

The QEMU kitchen is running: ${names[*]} on emulated LM3S6965 boards, bridge $bridge.
  in a browser:  http://$http/#token=$(cat "$state/token")
  status:        VMAC_TOKEN_FILE=$state/token $bin/vmac status --http $http
  type here, then Enter (each line goes to the named board's UART0):
    lights-1 toggle1 1        flip the kitchen wall switch
    washer-1 start 1          press the washer's start button
    washer-1 status           the board's frame counters and stack use
  programmes run at time scale $scale (VMAC_TIME_SCALE), reply deadline $deadline_us us (VMAC_QEMU_DEADLINE_US)${VMAC_SET:+ (VMAC_SET: $VMAC_SET)}
  Ctrl-C stops the host, then the boards, and removes the devices.

EOT
dispatch() {
	local line first
	while read -r line; do
		first=${line%% *}
		[ -z "$line" ] && continue
		if [ -p "$work/$first.in" ]; then
			echo "$line" >"$work/$first.in"
		else
			echo "run-qemu-kitchen: start the line with a board's name: ${names[*]}"
		fi
	done
}
dispatch <&3 &
reader=$!
wait -n "$host_pid" "${qemu_pids[@]}"
say "a process ended on its own; stopping the rest"
cleanup
