-- io.open: read a file
-- expect: attempt to index global 'io'
local driver = { name = "io_open", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	io.open('/etc/passwd')
end
return driver
