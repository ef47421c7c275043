-- Normal wash: warm fill, 8 minutes of washing at 45 RPM, a cold rinse,
-- and a 5-minute spin at 400 RPM. The driver locks the door before the
-- first step and unlocks it after the last one, once the drum is still
-- and the water is below the door.
return function(w)
	w.fill { temp = "warm", litres = 12 }
	w.wash { rpm = 45, minutes = 8 }
	w.drain()
	w.fill { temp = "cold", litres = 12 }
	w.wash { name = "rinse", rpm = 45, minutes = 4 }
	w.drain()
	w.spin { rpm = 400, minutes = 5 }
end
