---@meta _
-- LuaLS annotations of the plant API (docs/BOARD.md, "Plant models in
-- Lua"): the table a plant file returns. Declarations only: no code here
-- runs. tests/integration/test_types.py keeps the fields of vmac.Plant in
-- step with BOARD.md's table. In a plant file, say what it returns:
--   ---@type vmac.Plant
--   local plant = { io = { ... }, step = function(p, dt, out) ... end }
--   return plant

---What the board drives now, by the io's output names: a digital output
---is a boolean, `pwm` a number -1000..1000. The host refills it each step.
---@alias vmac.PlantOutputs table<string, boolean|number>

---An operator action: refuse a value with `return false, "why"`;
---anything else accepts it. Or the name of a digital input of io: a
---button, that input reads on for 0.5 s.
---@alias vmac.PlantAction fun(p: table, value: number): (boolean|nil), string?|string

---A plant model (docs/BOARD.md, "Plant models in Lua").
---@class vmac.Plant
---@field io table<string, vmac.Channel|vmac.IoSpec> the board's channels by name; inputs are read from the fields of p named alike
---@field step fun(p: table, dt: number, out: vmac.PlantOutputs): string? advances the machine by dt seconds (0 < dt <= 0.1); returns nothing while safe, else a text saying what is unsafe now
---@field state? table the initial state: the table p of step and the actions ({} when absent)
---@field actions? table<string, vmac.PlantAction> operator actions by name
---@field name? string the plant's name (default: the file's)
---@field driver? string the driver its board announces (default: name)
