return { name = "m", version = "1", io = { a = { "do0", board = 0 }, b = { "do0", board = 1 }, c = { "do0", board = 4294967295 },
  d = { "di0", board = -1 }, e = { "di0", board = 1.5 }, f = { "do1", board = 2 } },
  tick = function(dev) dev.out.a = true dev.out.b = true dev.out.c = true dev.out.f = true end }
