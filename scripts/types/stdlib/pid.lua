---@meta pid
-- LuaLS annotations of stdlib/pid.lua (docs/STDLIB.md, "pid"): a PID
-- controller with anti-windup. Declarations only.

local pid = {}

---The options of pid.new.
---@class vmac.PidSpec
---@field kp number output units per unit of error (required)
---@field ki? number output units per (unit of error x second), default 0
---@field kd? number output units per (unit of measurement / second), default 0
---@field out_min? number output clamp, default -inf
---@field out_max? number output clamp, default +inf
---@field i_min? number integral term limit, default out_min
---@field i_max? number integral term limit, default out_max
---@field d_filter_s? number derivative low-pass time constant, seconds (0: none)

---A PID controller; gains and limits may change between updates.
---@class vmac.Pid: vmac.PidSpec
---@field output number the last output
---@field p_term number
---@field i_term number
---@field d_term number
local Pid = {}

---@param spec vmac.PidSpec
---@return vmac.Pid
function pid.new(spec) end

---The output for this step, clamped to out_min..out_max.
---@param setpoint number
---@param measurement number
---@param dt number seconds since the last update (0: the previous output)
---@return number
function Pid:update(setpoint, measurement, dt) end

---Forget the integral, the last measurement and the output.
function Pid:reset() end

return pid
