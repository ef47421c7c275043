return { name = "m", version = "1",
  variables = { x = {}, y = { group = "G" }, z = { update = "timer:0" }, w = { update = "timer:86401" } },
  params = { x = { default = 1 }, p = { default = 2, min = 3 }, q = { default = "a", values = { "b" } } },
  commands = { x = {}, c = { arg = "nothing" } },
  tick = function() end }
