return { name = "m", version = "1", variables = { v = { set = true, min = 0, max = 10 } },
  params = { p = { default = "a", values = { "a", "b" }, persist = true }, n = { default = 1, min = 0, max = 5 } },
  commands = { go = { arg = "p" } },
  input = function(dev, name, value) return false, 42 end,
  tick = function(dev) dev.vars.v = dev.params.n * 2 end }
