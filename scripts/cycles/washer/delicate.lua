-- Delicate: cold water, a slow and short wash, two rinses, a gentle spin.
return function(w)
	w.fill { temp = "cold", litres = 15 }
	w.wash { rpm = 30, minutes = 5 }
	w.drain()
	for _ = 1, 2 do
		w.fill { temp = "cold", litres = 15 }
		w.wash { name = "rinse", rpm = 30, minutes = 3 }
		w.drain()
	end
	w.spin { rpm = 250, minutes = 3 }
end
