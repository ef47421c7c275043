---@meta cycle
-- LuaLS annotations of stdlib/cycle.lua (docs/STDLIB.md, "cycle"):
-- appliance cycles as sequences of named steps, run as a coroutine.
-- Declarations only.

local cycle = {}

---@alias vmac.CycleState "idle"|"running"|"paused"|"cancelling"|"done"|"cancelled"|"failed"

---The options of cycle.new, all optional.
---@class vmac.CycleOptions
---@field cleanup? fun(c: vmac.Cycle) run to its end after cancel() or a failed step
---@field hold? fun(outputs: table, c: vmac.Cycle) makes outputs safe while paused and when the cycle stops
---@field interlocks? vmac.Interlock[] pause this cycle while they hold
---@field steps? string[] the step names, for a body function
---@field outputs? table initial values of c.out

---A cycle: straight-line steps with waits, resumed once a driver tick.
---@class vmac.Cycle
---@field state vmac.CycleState
---@field phase vmac.CycleState the state under a pause
---@field step_name string? the current step
---@field step_index integer position in c.steps
---@field steps string[] the step names
---@field steps_begun integer c:step calls since start()
---@field pause_reasons string[]
---@field error string? after a failure, e.g. "fill: timed out after 120 s waiting for 12 l of water"
---@field error_step string? the step that failed
---@field time number bus time of the current tick
---@field dt number seconds since the previous tick
---@field started_at number?
---@field out table the cycle's outputs, kept across ticks
---@field inp table the driver's inputs, during a tick
local Cycle = {}

---A cycle of the steps body calls (or a list of {name, fn}).
---@param body fun(c: vmac.Cycle)|({[1]: string, [2]: fun(c: vmac.Cycle)}|{name: string, run: fun(c: vmac.Cycle)})[]
---@param options? vmac.CycleOptions
---@return vmac.Cycle
function cycle.new(body, options) end

---Once per driver tick: interlocks, then the steps, then the outputs.
---@param now number bus time, seconds, never decreasing
---@param inputs table the driver's named inputs (c.inp during the tick)
---@param outputs table the driver's named outputs
---@return vmac.CycleState
function Cycle:tick(now, inputs, outputs) end

---Arm the cycle; the first step runs on the next tick.
---@return true|nil ok
---@return string? message
function Cycle:start() end

---Add a pause reason (default "user").
---@param reason? string
---@return true|nil ok
---@return string? message
function Cycle:pause(reason) end

---Remove a pause reason (default "user").
---@param reason? string
---@return true|nil ok
---@return string? message
function Cycle:resume(reason) end

---Abandon the steps and start the cleanup.
---@return true|nil ok
---@return string? message
function Cycle:cancel() end

---True for running, paused and cancelling.
---@return boolean
function Cycle:active() end

---True for done, cancelled and failed.
---@return boolean
function Cycle:finished() end

---Run fn(c) as step name (inside the cycle's steps); returns what fn returns.
---@param name string
---@param fn fun(c: vmac.Cycle): any
---@return any
function Cycle:step(name, fn) end

---Wait s seconds of running time (inside the cycle's steps).
---@param s number
function Cycle:wait(s) end

---Return once cond(c) is true; raise after timeout_s seconds (nil: no limit).
---@param cond fun(c: vmac.Cycle): boolean
---@param timeout_s? number
---@param what? string said in the timeout's error
function Cycle:wait_until(cond, timeout_s, what) end

---As wait_until, but false on timeout instead of raising.
---@param cond fun(c: vmac.Cycle): boolean
---@param timeout_s? number
---@return boolean
function Cycle:try_wait_until(cond, timeout_s) end

---Wait for the next tick.
function Cycle:yield() end

---Running seconds since the cycle began.
---@return number
function Cycle:elapsed() end

---Running seconds in the current step.
---@return number
function Cycle:step_elapsed() end

---Running seconds left in the current wait, or nil.
---@return number?
function Cycle:wait_left() end

---Continue the old instance's cycle (hot reload: old is its plain copy);
---with now, on a new bus clock (recovery after a restart).
---@param old table
---@param now? number
---@return true|nil ok
---@return string? message
function Cycle:restore(old, now) end

return cycle
