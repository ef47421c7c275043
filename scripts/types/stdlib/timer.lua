---@meta timer
-- LuaLS annotations of stdlib/timer.lua (docs/STDLIB.md, "timer"):
-- stopwatches in bus time. Declarations only.

local timer = {}

---A stopwatch in bus time; time paused does not count.
---@class vmac.Timer
---@field running boolean
local Timer = {}

---A running stopwatch, started at now, with elapsed_s already on it.
---@param now number bus time, seconds
---@param elapsed_s? number seconds already on it (default 0)
---@return vmac.Timer
function timer.new(now, elapsed_s) end

---Seconds of running time since the start.
---@param now number
---@return number
function Timer:elapsed(now) end

---Start again from 0, running; after/every re-armed.
---@param now number
function Timer:reset(now) end

---Stop counting (no-op when paused).
---@param now number
function Timer:pause(now) end

---Count again (no-op when running).
---@param now number
function Timer:resume(now) end

---True while elapsed >= s (level).
---@param s number seconds
---@param now number
---@return boolean
function Timer:expired(s, now) end

---True once, at the first call with elapsed >= s (one-shot).
---@param s number seconds
---@param now number
---@return boolean
function Timer:after(s, now) end

---True once per period of running time, on the grid start + k x period.
---@param period number seconds, > 0
---@param now number
---@return boolean
function Timer:every(period, now) end

return timer
