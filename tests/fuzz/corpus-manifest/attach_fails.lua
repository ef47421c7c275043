return { name = "m", version = "1", attach = function(dev) error("nope") end, tick = function() end }
