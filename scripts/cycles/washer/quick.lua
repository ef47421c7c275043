-- Quick: cold fill, 4 minutes of washing, one rinse, a 2-minute spin.
return function(w)
	w.fill { temp = "cold", litres = 8 }
	w.wash { rpm = 45, minutes = 4 }
	w.drain()
	w.fill { temp = "cold", litres = 8 }
	w.wash { name = "rinse", rpm = 45, minutes = 2 }
	w.drain()
	w.spin { rpm = 400, minutes = 2 }
end
