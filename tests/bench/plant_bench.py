"""make bench, plant: what one step of a plant model in Lua costs, as
vmac-board steps it at 1 kHz (core/sim/),
next to the C washer stepped the same way in the same run
(tests/bench/plant_step.c, built beside bare_loop). The plant is the demo
kitchen's dryer, a user's plant (examples/kitchen/plants/dryer.lua). Run
through bench.py (--only plant). The goal (issue #33): under 5 us a step."""

import json
import os
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PLANT = os.path.join(ROOT, "examples", "kitchen", "plants", "dryer.lua")


def plant(args):
    """build/bench/plant_step PLANT --json, or {"error": why}."""
    exe = os.path.join(os.path.dirname(args.bare), "plant_step")
    if not os.access(exe, os.X_OK):
        return {"error": "%s not built (make %s)" % (exe, exe)}
    if not os.path.exists(PLANT):
        return {"error": "%s is missing" % PLANT}
    p = subprocess.run([exe, PLANT, "--json"], capture_output=True, text=True, timeout=300)
    if p.returncode != 0:
        return {"error": "plant_step exited %d: %s" % (p.returncode, p.stderr.strip()[:300])}
    return json.loads(p.stdout)


def report_plant(m):
    print("\nplant models, one step at 1 kHz as vmac-board takes it (tests/bench/plant_step.c, median of %s "
          "runs of %s steps):" % (m.get("repeats", "?"), m.get("steps", "?")))
    if "error" in m:
        print("  FAILED: %s" % m["error"])
        return
    us = m["us_per_step"]
    print("  %-44s %8.3f us/step" % ("the C washer (the baseline)", us["c_washer"]))
    print("  %-44s %8.3f us/step  %.1f x the C washer (goal: under 5 us)" % (
        "the Lua plant %s" % m.get("plant", "?"), us["lua"], m["ratio_to_c_washer"]))
