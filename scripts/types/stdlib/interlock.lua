---@meta interlock
-- LuaLS annotations of stdlib/interlock.lua (docs/STDLIB.md, "interlock"):
-- a condition that makes everything safe. Declarations only.

local interlock = {}

---The options of interlock.new.
---@class vmac.InterlockSpec
---@field name string also the cycle's pause reason
---@field trip fun(inputs: table, il: vmac.Interlock): boolean true while unsafe
---@field safe fun(outputs: table, inputs: table, il: vmac.Interlock) makes the outputs safe, every tick it holds
---@field rearm? fun(outputs: table, inputs: table, il: vmac.Interlock): boolean true when re-armed
---@field rearm_timeout? number seconds of bus time re-arming may take (needs rearm)

---@alias vmac.InterlockState "clear"|"tripped"|"rearming"|"fault"

---@class vmac.Interlock
---@field name string
---@field state vmac.InterlockState
---@field since number? bus time of the last change of state
---@field message string? why it is in "fault"
---@field rearmed boolean
local Interlock = {}

---@param spec vmac.InterlockSpec
---@return vmac.Interlock
function interlock.new(spec) end

---Evaluate trip on this tick's inputs; true while it holds.
---@param now number bus time, seconds
---@param inputs table
---@return boolean
function Interlock:update(now, inputs) end

---Tripped or fault: safe; re-arming: safe, then rearm; clear: nothing.
---@param outputs table
---@param inputs table
function Interlock:apply(outputs, inputs) end

---update and apply, for a driver without a cycle; true while it holds.
---@param now number
---@param inputs table
---@param outputs table
---@return boolean
function Interlock:tick(now, inputs, outputs) end

---Back to clear.
function Interlock:reset() end

---Take over state, since, message and rearmed from the old instance's copy;
---with now (a new bus clock), since becomes now.
---@param old table
---@param now? number
function Interlock:restore(old, now) end

return interlock
