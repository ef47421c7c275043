---@meta _
-- LuaLS annotations of the driver API (docs/DRIVERS.md): the manifest a
-- driver file returns, its callbacks, `dev`, `inputs` and the sandbox's own
-- globals (vmac, os.clock, require). Declarations only: no code here runs.
-- tests/integration/test_types.py keeps these in step with the docs.
-- In a driver, say what the file returns:
--   ---@type vmac.Driver
--   local driver = { name = "porch", version = "1.0.0", io = { ... } }

---A channel of the board (DRIVERS.md, "io"): di0..di7 digital inputs
---(booleans), ai0 and ai1 analog inputs (counts x scale + offset), encoder
---(a 32-bit count that wraps), do0..do6 digital outputs (booleans, nil =
---off), pwm (drive -1000..1000, nil = 0).
---@alias vmac.Channel "di0"|"di1"|"di2"|"di3"|"di4"|"di5"|"di6"|"di7"|"ai0"|"ai1"|"encoder"|"do0"|"do1"|"do2"|"do3"|"do4"|"do5"|"do6"|"pwm"

---A value the host publishes or an operator sets.
---@alias vmac.Value number|boolean|string

---A channel with its scaling, or on another board of the machine.
---@class vmac.IoSpec
---@field [1] vmac.Channel
---@field scale? number counts x scale + offset (default 1)
---@field offset? number (default 0)
---@field unit? string for people
---@field board? integer the minor id of the board whose channel this is

---Hints for Home Assistant (DRIVERS.md, "Home Assistant hints").
---@class vmac.HaHints
---@field device_class? string HA's device class of the entity
---@field state_class? "measurement"|"total"|"total_increasing"
---@field precision? integer decimals, 0..6
---@field entity_category? "config"|"diagnostic"
---@field enabled_by_default? boolean
---@field step? number HA's number step, at least 0.001 (params, settable variables)

---A setting with its type, range and unit (DRIVERS.md, "params").
---@class vmac.ParamSpec: vmac.HaHints
---@field default vmac.Value required; gives the param its type
---@field min? number
---@field max? number
---@field values? string[] the allowed strings
---@field persist? boolean an operator's persistent value is kept in the host's store
---@field unit? string
---@field label? string

---A published value (DRIVERS.md, "variables").
---@class vmac.VariableSpec: vmac.HaHints
---@field update? "auto"|string "auto" (default: every tick it changed) or "timer:N" (every N s of bus time)
---@field group? string published together with the rest of its group, from one tick
---@field set? boolean an operator may set it (input(dev, name, value))
---@field unit? string
---@field label? string
---@field min? number
---@field max? number
---@field values? string[]

---An operator command (DRIVERS.md, "commands").
---@class vmac.CommandSpec
---@field label? string
---@field arg? string a variable or param whose allowed values the argument must have

---When a machine's inputs are latched and outputs released, by the boards'
---clocks (DRIVERS.md, "timing"; TIME.md, "The patterns").
---@class vmac.Timing
---@field pattern "phase"|"offsets"|"arrival" phase (the default): both at the slot's start + the host's lead
---@field input_us? integer offsets: inputs latched this long after the slot's planned start
---@field output_us? integer offsets: outputs released this long after it

---What a driver file returns: the manifest and the callbacks (DRIVERS.md,
---"The manifest", "The callbacks"). The host refuses a driver without tick.
---@class vmac.Driver
---@field name string the name the board announces (the file name)
---@field version string
---@field level? integer service period: every 2^level slots
---@field description? string one line for people
---@field io table<string, vmac.Channel|vmac.IoSpec> the board's channels under names
---@field params? table<string, vmac.ParamSpec>
---@field variables? table<string, vmac.VariableSpec> at most 24
---@field commands? table<string, vmac.CommandSpec>
---@field ui? table free-form hints for user interfaces (title, icon, plots)
---@field jit? boolean ask for the LuaJIT compiler (honoured only with allow_jit)
---@field timing? vmac.Timing when inputs are latched and outputs released (default: phase)
---@field attach? fun(dev: vmac.Dev) once, before the first tick
---@field tick? fun(dev: vmac.Dev, inputs: vmac.Inputs) every service period (required)
---@field input? fun(dev: vmac.Dev, name: string, value: vmac.Value): true|nil, string? operator input; nil, message refuses it
---@field detach? fun(dev: vmac.Dev, reason: string) the machine is unloaded in order
---@field migrate? fun(dev: vmac.Dev, old_state: table) hot reload: continue from the old dev.state (plain data)
---@field recover? fun(dev: vmac.Dev, saved: vmac.Saved) the machine attaches and the host holds a checkpoint

---Every named input of the driver's io, and the bus time. The same table
---every tick: copy values out, keep no reference to it.
---@class vmac.Inputs
---@field time number bus time in seconds, never decreasing
---@field [string] boolean|number

---A board of the machine, primary first in dev.boards.
---@class vmac.BoardRef
---@field name string
---@field minor integer
---@field t number when this board's inputs in this tick were sampled (bus time, s; as dev.t)

---The last checkpoint of dev.state, as recover(dev, saved) gets it.
---@class vmac.Saved
---@field state table a plain-data copy of dev.state at the checkpoint
---@field age_s number seconds from the checkpoint to now (wall clock); math.huge when the clock was set back since
---@field version string the driver version that wrote it
---@field time number when it was written (Unix time, seconds)
---@field restarted boolean true after a host restart; false when the machine came back after a drop

---The machine, as every callback gets it (DRIVERS.md, "dev").
---@class vmac.Dev
---@field name string the machine's name (its primary board's name)
---@field driver string the driver's name
---@field version string the driver's version
---@field out table<string, boolean|number|nil> named outputs; they keep their values across ticks
---@field vars table<string, vmac.Value|nil> published variables: numbers, booleans, strings of at most 63 bytes
---@field params table<string, vmac.Value> parameter values (read them, do not write them)
---@field state table the driver's own; copied to migrate and kept in checkpoints
---@field boards vmac.BoardRef[] the boards attached, primary first
---@field level integer the level the machine is serviced at now
---@field t number when the primary's inputs in this tick were sampled (bus time, s): its latch time, or the reply's arrival
local Dev = {}

---Ask for another service level (0..max_level); the change comes at a slot
---boundary the scheduler picks.
---@param n integer
---@return true|nil ok
---@return string? message
function Dev:set_level(n) end

---Release the outputs this tick sets s seconds after the planned start of
---the slot that carries them (from the pattern's output instant to the
---period; DRIVERS.md, "timing"), for this tick only.
---@param s number seconds
---@return true|nil ok
---@return string? message why not (outside the range, or the machine acts on arrival)
function Dev:output_at(s) end

---Record an event (kind `driver`) for people; at most 10 per second.
---@param text string
function Dev:event(text) end

---Ask the host to save dev.state at the end of this call.
function Dev:checkpoint() end

---What the sandbox adds to the globals (DRIVERS.md, "The sandbox").
---@class vmac.lib
---@field version string the driver API, e.g. "0.2"
vmac = {}

---Every programme of this driver (cycles/NAME/*.lua): file name without
---.lua -> what that file returned. Only while the driver file loads.
---@return table<string, any>
function vmac.cycles() end

---Bus time in seconds (the clock of inputs.time; 0 while the file loads).
---The only function of os in the sandbox.
---@return number
function os.clock() end
