-- Delicate: gentler heat for longer, 50 C for 40 minutes, then 5 minutes
-- of tumbling without heat.
return function(d)
	d.dry { temp_c = 50, minutes = 40 }
	d.cool { minutes = 5 }
end
