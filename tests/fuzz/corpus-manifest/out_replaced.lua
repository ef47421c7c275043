return { name = "m", version = "1", io = { a = "do0" }, variables = { v = {} },
  tick = function(dev) dev.out = 5; dev.vars = nil end }
