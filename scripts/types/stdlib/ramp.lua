---@meta ramp
-- LuaLS annotations of stdlib/ramp.lua (docs/STDLIB.md, "ramp"):
-- setpoints with bounded rate and acceleration. Declarations only.

local ramp = {}

---The options of ramp.new.
---@class vmac.RampSpec
---@field accel number units/s^2, > 0 (math.huge: no limit)
---@field decel? number units/s^2, default accel
---@field max_rate? number units/s, default no limit
---@field value? number starting value, default 0, at rest

---A setpoint generator with a trapezoidal rate profile.
---@class vmac.Ramp
---@field value number
---@field rate number units/s
---@field target number
local Ramp = {}

---@param spec vmac.RampSpec
---@return vmac.Ramp
function ramp.new(spec) end

---The continuous-time plan of one move from rest to rest.
---@param spec {accel: number, decel?: number, max_rate?: number, from: number, to: number}
---@return {accel_s: number, cruise_s: number, decel_s: number, total_s: number, peak_rate: number}
function ramp.profile(spec) end

---The value after dt seconds toward target.
---@param target number
---@param dt number seconds
---@return number
function Ramp:update(target, dt) end

---True at the last target, at rest.
---@return boolean
function Ramp:done() end

---Set the value, at rest (rate 0).
---@param value number
function Ramp:reset(value) end

return ramp
