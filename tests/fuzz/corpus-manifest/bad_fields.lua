return { name = "m", version = "1", level = 11, jit = 1, ui = 2, description = {}, extra = 1, [1] = 2,
  io = { [1] = "do0", Bad = "do1" }, tick = 3 }
