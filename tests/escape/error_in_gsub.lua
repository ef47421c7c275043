-- an error inside a gsub replacement function
-- expect: gsub boom
local driver = { name = "error_in_gsub", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.gsub('aaa', 'a', function() error('gsub boom') end)
end
return driver
