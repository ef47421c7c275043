-- a manifest whose missing fields loop forever when the host reads them
-- expect: time budget exceeded
return setmetatable({ name = "manifest_metatable", version = "1", io = { lamp = "do0" }, tick = function() end },
	{ __index = function() while true do end end })
