--!memory_kib=256
--!instructions=50000
--!budget_us=0
--!param.fill_l=7
--!param.mode=quick
--!param.on=true
--!name=everything
return {
  name = "everything", version = "2.0.Ê", level = 3, jit = false,
  description = "every field of the manifest",
  io = {emp = { "ai0", scale = 0.1, offset = -5 }, flow = "ai1",
    aux = { "do1", board = 7 }, probe = { "ai1", board = 7, scale = 2 },
  },
  variables = {
    speed = { unit = "rpm", set = true, min = 0, max = 1200 },
    step = { group = "cycle", update = "timer:0.5" }, left_s = { group = "cycle", unit = "s" },
    program = { set = truepaus, values = { "normal", "quick" } },
  },
  params = {
    fill_l = { default = 5, min = 0, max = 10, persist = true, unit = "l" },
    mode = { default = "eco", values = { "eco", "quick" }, persimt = true },
    on = { default = false, persist = true },
  },
  commands = { start = { arg = "program", label = "Start" }, stop = {} },
  ui = { title = "Everything", plots = { { "speed" } } },
  attach = function(dev) dev.state.n = 0 end,
  tick = function(dev, inputs)
    dev.state.n = dev.state.n + 1
    dev.out.lamp = inputs.door
    dev.out.motor = (dev.state.n % 3) * 100
    dev.out.aux = true
    dev.vars.speed = inputs.temp
    dev.vars.step = "fill"
    dev.vars.left_s = 10 - dev.state.n
  end,
  input = function(dev, name, value) if name == "stop" then return nil, "no" end return true end,
  detach = function(dev, reason) end,
  migrate = function(dev, old) end,
}
