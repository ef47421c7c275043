local timer = require("timer")
local pid = require("pid")
return { name = "m", version = "1", io = { m = "pwm", t = "ai0" },
  attach = function(dev) dev.state.pid = pid.new({ kp = 1, ki = 0, kd = 0 }) end,
  tick = function(dev, inputs) dev.out.m = 0 end }
