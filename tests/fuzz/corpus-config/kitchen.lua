-- kitchen.lua
bus = "239.255.86.77:5870"
http = "0.0.0.0:8080"
slice_us = 1000           -- 10 slices of 1 ms: 10 ms slots
reply_deadline_us = 4000
driver = {                -- settings of one driver: driver.NAME.KEY
	washer = { memory_kib = 8192, param = { time_scale = 0.1 } },
}
