return { name = "m", version = "1", io = { a = "do0", b = "do0", c = { "pwm", board = 1 }, d = { "pwm", board = 1 } },
  tick = function(dev) dev.out.a = true end }
