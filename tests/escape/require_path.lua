-- require with a path out of stdlib/
-- expect: not a stdlib module name
require '../../../etc/passwd'
return { name = "require_path", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = true end }
