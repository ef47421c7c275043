-- memory creeping under pcall in tick, every refusal caught (three lines that end a host in which pcall can swallow the cap)
-- expect: memory cap exceeded
return { name = "creep_tick", version = "1.0.0", io = { do0 = "do0", di0 = "di0" },
  tick = function(dev, inputs) G = G or {} N = (N or 0) + 1
    for i = 1, 400 do if not pcall(function() G[#G+1] = {N, i} end) then break end end end }
