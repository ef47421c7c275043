local ms = 1000
slice_us = ms / 10
slices_per_slot = 10
for i = 1, 3 do max_level = i * 4 end
bus = "239.255.86.77:" .. (5870 + 0)
driver = { lights = { instructions = 1e6, budget_us = "500", param = { fill_l = 5, mode = "eco", on = true } } }
driver.washer = { param = {} }
