-- dofile: run a file of the host
-- expect: attempt to call global 'dofile'
dofile('/etc/passwd')
return { name = "dofile_passwd", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = true end }
