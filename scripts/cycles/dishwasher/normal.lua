-- Normal: a pre-rinse, a 20-minute wash, two rinses, then a dry.
return function(d)
	d.fill()
	d.wash { name = "pre-rinse", minutes = 3 }
	d.drain()
	d.fill()
	d.wash { minutes = 20 }
	d.drain()
	for _ = 1, 2 do
		d.fill()
		d.wash { name = "rinse", minutes = 4 }
		d.drain()
	end
	d.dry { minutes = 10 }
end
