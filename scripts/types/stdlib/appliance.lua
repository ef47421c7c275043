---@meta appliance
-- LuaLS annotations of stdlib/appliance.lua (docs/STDLIB.md, "appliance"):
-- programmes, buttons and commands of an appliance. Declarations only.

local appliance = {}

---The options of appliance.new.
---@class vmac.ApplianceSpec
---@field cycle vmac.Cycle the cycle that runs the chosen programme
---@field programs table<string, any> name -> programme (what vmac.cycles() returned)
---@field idle_level integer service level when idle
---@field run_level integer service level while a programme runs
---@field can_start? fun(): string? nil to allow a start, or a message saying why not

---@class vmac.Appliance: vmac.ApplianceSpec
---@field chosen string? the programme started last
local Appliance = {}

---@param spec vmac.ApplianceSpec
---@return vmac.Appliance
function appliance.new(spec) end

---Start programme name (nil: dev.params.program).
---@param dev vmac.Dev
---@param name? string
---@return true|nil ok
---@return string? message
function Appliance:start(dev, name) end

---The programme chosen by the last start, for the cycle's body.
---@return any
function Appliance:programme() end

---Once per tick, before the cycle's tick: rising edges start and cancel.
---@param dev vmac.Dev
---@param start boolean
---@param cancel boolean
function Appliance:buttons(dev, start, cancel) end

---Once per tick, after the cycle's tick: the levels, dev.vars and checkpoints.
---@param dev vmac.Dev
function Appliance:publish(dev) end

---The commands start, pause, resume and cancel, as driver.input returns.
---@param dev vmac.Dev
---@param name string
---@param value vmac.Value
---@return true|nil ok
---@return string? message
function Appliance:input(dev, name, value) end

---Take over the old instance's appliance (hot reload), or a checkpoint's
---with now (recovery after a restart).
---@param old table
---@param now? number
---@return true|nil ok
---@return string? message
function Appliance:restore(old, now) end

---In recover(dev, saved): take over old and say what became of it.
---@param dev vmac.Dev
---@param old table the appliance in saved.state
---@param age_s number saved.age_s
---@param max_age_s number older than this: cancelled
---@return "idle"|"ended"|"cancelling"|"cancelled"|"resume"
function Appliance:recover(dev, old, age_s, max_age_s) end

---At the first tick after "resume": why is what the plant says against
---going on (nil: nothing).
---@param dev vmac.Dev
---@param why? string
function Appliance:agree(dev, why) end

return appliance
