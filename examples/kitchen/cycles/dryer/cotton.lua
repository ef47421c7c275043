-- Cotton: warm up to 70 C, dry at 70 C for 50 minutes while the drum
-- tumbles, then 10 minutes of tumbling without heat to cool the laundry.
return function(d)
	d.dry { temp_c = 70, minutes = 50 }
	d.cool { minutes = 10 }
end
