-- require 'ffi': the foreign function interface
-- expect: no such stdlib module
require 'ffi'
return { name = "require_ffi", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = true end }
