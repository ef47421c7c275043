-- Rinse and hold: one short rinse, no drying.
return function(d)
	d.fill()
	d.wash { name = "rinse", minutes = 5 }
	d.drain()
end
