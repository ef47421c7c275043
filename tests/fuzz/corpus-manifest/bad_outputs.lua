return { name = "m", version = "1", io = { a = "do0", m = "pwm" }, variables = { v = {} },
  tick = function(dev) dev.out.a = 1; dev.out.m = 0/0; dev.vars.v = {} end }
