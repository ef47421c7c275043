--!memory_kib=1
--!param.nothing=3
--!param.n=abc
--!param.b=maybe
--!colour=blue
return { name = "m", version = "1", params = { n = { default = 1 }, b = { default = true } }, tick = function() end }
