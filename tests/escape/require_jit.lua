-- require 'jit': turn the compiler on
-- expect: no such stdlib module
require 'jit'
return { name = "require_jit", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = true end }
